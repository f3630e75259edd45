"""scanner_sim: the survey-mission simulator around the MULS lidar model.

The Python API (``docs/python-api.md``)::

    import scanner_sim
    config = scanner_sim.load_scene("cable_survey")
    result = scanner_sim.simulate_pass(config, scanner_sim.PassOptions(max_pulses=5000, progress=False))
    result.points.xyz, result.points.classification, result.summary["points"]

The public names load on first use (a module ``__getattr__``), so that ``import scanner_sim`` and the command
line's ``--help`` do not import the pipeline, the kernels or the ray tracer behind them.
"""

from __future__ import annotations

from muls.infra.lazy_names import lazy_names

#: public name -> the module that defines it.
_WHERE = {
    **dict.fromkeys(("ConfigError", "SceneConfig", "load_scene", "parse_scene", "shipped_scenes"), "scanner_sim.config"),
    **dict.fromkeys(("DropoutRecords", "PointRecords"), "scanner_sim.records.point_records"),
    **dict.fromkeys(("SurveyPlan", "plan_survey"), "scanner_sim.studies.planning"),
    **dict.fromkeys(("PassResult", "run_pass", "simulate_pass"), "scanner_sim.survey.pipeline"),
    **dict.fromkeys(("PassOptions", "PassSetup"), "scanner_sim.survey.setup"),
    "__version__": "scanner_sim.version",
    **dict.fromkeys(("Scene", "build_scene"), "scanner_sim.world.scene"),
}

__all__, __getattr__, __dir__ = lazy_names(__name__, _WHERE)
