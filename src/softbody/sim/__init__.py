"""The data model (builder, model, state, control) and the simulator."""

from softbody.sim.builder import ModelBuilder
from softbody.sim.control import Control
from softbody.sim.model import Model
from softbody.sim.simulator import Simulator
from softbody.sim.state import State, StepHistory

__all__ = ["Control", "Model", "ModelBuilder", "Simulator", "State", "StepHistory"]
