"""The solver wing: Position Based Fluids, a module per stage of Algorithm 1, importing only ``pbf.scene``,
Taichi and NumPy. Its public face is imported here."""

from pbf.solver.backend import ARCHES, ENV_VAR, BackendError, start_backend
from pbf.solver.bodies import STATE_LAYOUT, quaternion_matrix_np
from pbf.solver.constants import scene_constants
from pbf.solver.grid import NeighbourList
from pbf.solver.model import Control, Model, Push, allocation
from pbf.solver.scan import ExclusiveScan
from pbf.solver.simulation import STAGES, Neighbourhood, Readout, Simulation, Solids, StageHook
from pbf.solver.state import Snapshot

__all__ = [
    "ARCHES",
    "ENV_VAR",
    "BackendError",
    "ExclusiveScan",
    "Control",
    "Model",
    "NeighbourList",
    "Neighbourhood",
    "Push",
    "Readout",
    "STAGES",
    "STATE_LAYOUT",
    "Simulation",
    "Snapshot",
    "Solids",
    "StageHook",
    "allocation",
    "quaternion_matrix_np",
    "scene_constants",
    "start_backend",
]
