"""Sphinx configuration of softbody's documentation.

Why Sphinx (with MyST Markdown, myst-nb and the furo theme) rather than MkDocs: the API
reference comes from the docstrings through autodoc and napoleon, which read the
NumPy-style sections softbody's docstrings use; myst-nb executes the tutorials as
notebooks during the build, so a tutorial that no longer runs fails the build; and
``-W`` turns every broken cross-reference into an error. NumPy, SciPy and trimesh's
users know its layout. The scene keys, the command line, the benchmark pages and the
verification page are generated at build time by ``_ext/softbody_docs.py``.

Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html``.
"""

import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

project = "softbody"
author = "softbody contributors"
copyright = "softbody contributors"  # noqa: A001

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # MathJax ships with the site: equations render offline too
    "sphinx.ext.viewcode",
    "softbody_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints", "jupyter_execute"]

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# tutorials run at every build; a cell that raises fails the build (-W)
nb_execution_mode = "force"
nb_execution_timeout = 300
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

autodoc_default_options = {"members": True}
autodoc_member_order = "bysource"
# softbody.sweep's Dask and pyarrow come with the sweep extra, not with the docs one
autodoc_mock_imports = ["dask", "distributed", "pyarrow"]
autodoc_typehints = "description"
# the docstrings give each parameter's type with its unit and shape; the hints only fill
# in what a docstring leaves out, and NumPy's ArrayLike stays one word
autodoc_typehints_description_target = "documented_params"
autodoc_type_aliases = {"ArrayLike": "ArrayLike", "NDArray": "NDArray"}
autodoc_typehints_format = "short"
autosummary_generate = False
napoleon_numpy_docstring = True
napoleon_google_docstring = False
# a type named in prose is not a cross-reference target
nitpicky = False

html_theme = "furo"
html_title = "softbody"
html_static_path = []
napoleon_use_ivar = True  # a class's Attributes section is a field list, not a second entry

# "tuple of (time [s], value)" in a type names a word, not an object
suppress_warnings = ["ref.python"]

exclude_patterns += ["benchmarks/notes/*", "generated/integrator-table.md",
                     "generated/benchmark-summary.md"]  # included only


_SECTION = re.compile(r"^(Parameters|Attributes|Returns|Yields|Raises|Other Parameters)$")
_ENTRY = re.compile(r"^\*{0,2}\w+(, \*{0,2}\w+)*( :.*)?$")


def _plain_text_docstrings(app, what, name, obj, options, lines):
    """softbody's docstrings are plain text read in a terminal. Before napoleon reads
    them: ``|x|`` is an absolute value, not a substitution; and a paragraph may follow a
    Parameters section after a blank line, which napoleon would read as more parameters,
    so it is put under a Notes heading."""
    out: list[str] = []
    in_section = False
    for k, line in enumerate(lines):
        stripped = line.lstrip()
        if stripped and not stripped.startswith(("|", "+")):
            line = line.replace("|", "\\|")
        nxt = lines[k + 1] if k + 1 < len(lines) else ""
        if _SECTION.match(line) and nxt.startswith("---"):
            in_section = True
        elif nxt.startswith("---") and line and not line[0].isspace():
            in_section = False
        elif (
            in_section and line and not line[0].isspace() and out and out[-1] == ""
            and not _ENTRY.match(line)
        ):
            out.extend(["Notes", "-----"])
            in_section = False
        out.append(line)
    lines[:] = out


def setup(app):
    app.connect("autodoc-process-docstring", _plain_text_docstrings, priority=400)
