"""Progress bars for long :class:`~softbody.Simulator` calls (tqdm, notebook-aware).

The compiled loop calls a run's callback with the steps done every 50 ms or so (between
two steps, where it also runs Python's signal handlers), so a bar costs the run nothing and
the steps are the same with or without one.
"""

from __future__ import annotations

import sys
import time

#: ``progress=None``: a bar for a call expected to take longer than this [s] in all ...
AUTO_SECONDS = 2.0
#: ... judged from its speed once it has run this long [s].
AUTO_AFTER = 0.5


def interactive() -> bool:
    """Whether a live bar can be seen: stderr is a terminal, or this is a Jupyter kernel."""
    try:
        if sys.stderr is not None and sys.stderr.isatty():
            return True
    except (AttributeError, ValueError):  # a replaced or closed stderr
        pass
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})


def _bar(total: int, initial: int):
    """A tqdm bar of ``total`` steps on stderr: tqdm.auto's (a widget in a notebook), or
    the text bar where the widget cannot be made (no ipywidgets)."""
    from tqdm import tqdm as text_bar
    from tqdm.auto import tqdm as auto_bar

    options = {"total": total, "initial": initial, "unit": "step", "unit_scale": True,
               "desc": "simulating", "dynamic_ncols": True}  # fmt: skip
    try:
        return auto_bar(**options)
    except ImportError:  # tqdm.notebook without ipywidgets
        return text_bar(file=sys.stderr, **options)


class RunProgress:
    """The progress of one ``Simulator.run`` or ``advance`` call of ``total`` steps of
    ``dt`` [s] from time ``t0`` [s].

    ``mode`` True: a bar from the start; None: a bar once the call has run
    ``AUTO_AFTER`` s if it is then expected to take longer than ``AUTO_SECONDS`` in all,
    and only where it can be seen (:func:`interactive`); False: none.
    """

    def __init__(self, total: int, t0: float, dt: float, mode: bool | None):
        self.total, self.t0, self.dt = int(total), float(t0), float(dt)
        self.auto = mode is None
        self.started = time.perf_counter()
        self.bar = _bar(self.total, 0) if mode else None

    @classmethod
    def start(cls, total: int, t0: float, dt: float, mode: bool | None) -> RunProgress | None:
        """The call's progress, or None when it shows none (``mode`` False, or None where
        no bar can be seen)."""
        if mode is not None and not isinstance(mode, bool):
            raise ValueError(f"progress must be True, False or None (auto), got {mode!r}")
        if mode is False or (mode is None and not interactive()):
            return None
        return cls(total, t0, dt, mode)

    def callback(self, before: int):
        """The core's callback for a compiled call that starts ``before`` steps into this
        one: it gets the steps that call has done."""
        return lambda done: self.show(before + done)

    def show(self, done: int) -> None:
        """``done`` of the call's steps are done."""
        if self.bar is None:
            elapsed = time.perf_counter() - self.started
            if not (self.auto and done > 0 and elapsed >= AUTO_AFTER):
                return
            if elapsed * self.total / done < AUTO_SECONDS:
                self.auto = False  # a short call: no bar, and no more checks
                return
            self.bar = _bar(self.total, done)
        self.bar.set_postfix_str(f"t = {self.t0 + done * self.dt:.6g} s", refresh=False)
        self.bar.update(done - self.bar.n)

    def close(self, done: int) -> None:
        """The call ended with ``done`` steps done: the bar shows them and closes."""
        if self.bar is not None:
            self.show(done)
            self.bar.close()
