"""NumPy forms of force terms used outside the compiled core."""
