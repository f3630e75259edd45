"""scanner_sim: the survey-mission simulator around the MULS lidar model.

The Python API (``docs/python-api.md``)::

    import scanner_sim
    config = scanner_sim.load_scene("cable_survey")
    result = scanner_sim.simulate_pass(config, scanner_sim.PassOptions(max_pulses=5000, progress=False))
    result.points.xyz, result.points.classification, result.summary["points"]
"""

import muls  # noqa: F401  first: it sets where numba caches kernels (muls/kernel_cache.py)

from .config import ConfigError, SceneConfig, load_scene, parse_scene, shipped_scenes
from .records import DropoutRecords, PointRecords
from .scene import Scene, build_scene
from .survey import PassOptions, PassResult, PassSetup, run_pass, simulate_pass
from .version import __version__

__all__ = [
    "ConfigError", "DropoutRecords", "PassOptions", "PassResult", "PassSetup", "PointRecords", "Scene",
    "SceneConfig", "__version__", "build_scene", "load_scene", "parse_scene", "run_pass", "shipped_scenes",
    "simulate_pass",
]
