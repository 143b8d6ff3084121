"""Browser viewer (viser): ``softbody.viewer.show(model, state, simulator)``.

Imported lazily: ``import softbody`` does not load viser.
"""

from __future__ import annotations


def show(*args, **kwargs):
    """See :func:`softbody.viewer.app.show`."""
    from softbody.viewer.app import show as _show

    return _show(*args, **kwargs)


__all__ = ["show"]
