"""Pictures of a model's state: the software rasteriser, the frame composer, video and
plots. Nothing is imported here; import the submodules."""
