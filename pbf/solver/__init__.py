"""The solver wing: the physics of Position Based Fluids, a module per stage of Algorithm 1.

Its public face (what the application and the studies use) is imported here. The modules inside
import only the scene schema (``pbf.scene``), Taichi and NumPy: no plotting, command line or images.
"""

from pbf.solver.backend import ARCHES, ENV_VAR, BackendError, start_backend
from pbf.solver.bodies import STATE_LAYOUT, quaternion_matrix_np
from pbf.solver.constants import scene_constants
from pbf.solver.grid import NeighbourList
from pbf.solver.model import Control, Model, Push, allocation
from pbf.solver.simulation import STAGES, Neighbourhood, Readout, Simulation, StageHook
from pbf.solver.state import Snapshot

__all__ = [
    "ARCHES",
    "ENV_VAR",
    "BackendError",
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
    "StageHook",
    "allocation",
    "quaternion_matrix_np",
    "scene_constants",
    "start_backend",
]
