"""Browser viewer (viser): ``softbody.viewer.show(model, state, simulator)``.

Imported lazily: ``import softbody`` does not load viser.
"""

from __future__ import annotations

import argparse


def show(*args, **kwargs):
    """See :func:`softbody.viewer.app.show`."""
    from softbody.viewer.app import show as _show

    return _show(*args, **kwargs)


def port_number(text: str) -> int:
    """``--port`` of ``softbody view``: an integer in 0..65535 (0: any free port)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be in 0..65535, got {text}")
    return value


__all__ = ["port_number", "show"]
