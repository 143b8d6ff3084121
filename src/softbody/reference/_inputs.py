"""The control as the kernels read it, from whatever a caller holds."""

from __future__ import annotations

import numpy as np

from softbody.sim.control import Control, ControlData, control_data
from softbody.sim.model import Model


def control_arrays(model: Model, control: Control | ControlData | None = None) -> ControlData:
    """``control`` as the kernel arrays (``ControlData``): None gives the neutral inputs,
    a :class:`Control` is checked and written, ``ControlData`` is returned as it is."""
    if control is None:
        return control_data(model)
    if isinstance(control, Control):
        return control.write(model, control_data(model))
    return control


def wind(model: Model, control: ControlData) -> np.ndarray:
    """The air velocity [m/s] (3,) of this call: ``control.wind`` when set (finite), else
    the model's (the kernels' rule: all NaN means "the model's")."""
    w = np.asarray(control.wind, dtype=np.float64)
    return w.copy() if np.all(np.isfinite(w)) else np.asarray(model.wind, dtype=np.float64)
