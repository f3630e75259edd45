"""scanner_sim: the survey-mission simulator around the MULS lidar model.

The Python API (``docs/python-api.md``)::

    import scanner_sim
    config = scanner_sim.load_scene("cable_survey")
    result = scanner_sim.simulate_pass(config, scanner_sim.PassOptions(max_pulses=5000, progress=False))
    result.points.xyz, result.points.classification, result.summary["points"]
"""

from scanner_sim.config import ConfigError, SceneConfig, load_scene, parse_scene, shipped_scenes
from scanner_sim.records.point_records import DropoutRecords, PointRecords
from scanner_sim.studies.planning import SurveyPlan, plan_survey
from scanner_sim.survey.pipeline import PassResult, run_pass, simulate_pass
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.version import __version__
from scanner_sim.world.scene import Scene, build_scene

__all__ = [
    "ConfigError", "DropoutRecords", "PassOptions", "PassResult", "PassSetup", "PointRecords", "Scene",
    "SceneConfig", "SurveyPlan", "__version__", "build_scene", "load_scene", "parse_scene", "plan_survey", "run_pass",
    "shipped_scenes", "simulate_pass",
]
