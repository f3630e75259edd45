"""What made a pass, in full (docs/outputs.md#provenance): the water as the model resolved it, the instrument as
it fired, every value given on top of the scene file, the software and output-format versions, and the fingerprint
of the pass's inputs that a campaign's re-run compares (:func:`inputs_fingerprint`).

summary.json holds the block under ``provenance``, and every point cloud's ``muls-scanner`` metadata VLR under
``pass_metadata.provenance`` (:func:`point_cloud_provenance`: the block without what changes no point). Neither
holds a clock time, so a seed still fixes the files' bytes.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from muls.water.properties import PHASE_FUNCTION, RANGE_DEPENDENT_MODELS, Water
from scanner_sim.config import SceneConfig
from scanner_sim.config.crs import crs_provenance
from scanner_sim.config.geometry import MeshObject
from scanner_sim.fidelity import FidelityLevel
from scanner_sim.io.summary import jsonable
from scanner_sim.version import __version__

#: Scene keys that change no bit of a pass's points (a seed fixes a pass whatever its chunk size): the point
#: clouds' provenance leaves them out, so that their bytes stay the same.
POINT_NEUTRAL_KEYS = ("survey.chunk_pulses",)

#: Version of the layout of a pass's files (names, summary.json's keys, the LAS dimensions and metadata): a pass
#: written under another version is run again by a campaign.
OUTPUT_FORMAT_VERSION = 1


def water_provenance(config: SceneConfig, water: Water) -> dict:
    """The water a pass ran in, as the model resolved it: its name (the preset's, or the scene's for a custom
    water) and source; a, b, c [1/m], the group index; the attenuation rule and the backscatter rule; the phase
    function the range-dependent attenuation rules and the Monte Carlo's tables integrate (None under a
    coefficient rule: ``k_lidar``, ``c``, ``kd``); beta(180 deg) [1/(m sr)] and where it comes from; K_d [1/m]
    (the ``kd`` rule's); the background radiance [W/(m^2 sr nm)]."""
    return {
        "name": config.water.preset or water.name,
        "preset": config.water.preset,
        "source": water.source,
        "absorption_per_m": water.absorption_per_m,
        "scattering_per_m": water.scattering_per_m,
        "attenuation_per_m": water.attenuation_per_m,
        "group_index": water.group_index,
        "attenuation_model": water.attenuation_model,
        "backscatter_model": water.backscatter_model,
        "phase_function": water.phase_function if water.attenuation_model == "monte_carlo" else
        PHASE_FUNCTION if water.attenuation_model in RANGE_DEPENDENT_MODELS else None,
        "beta_pi_per_m_sr": water.beta_pi_per_m_sr,
        "beta_pi_source": water.beta_pi_source,
        "kd_per_m": water.kd_estimate_per_m,
        "background_radiance_w_m2_sr_nm": config.water.background_radiance_w_m2_sr_nm,
    }


def pass_provenance(config: SceneConfig, water: Water, instrument, level: FidelityLevel, fingerprint: str) -> dict:
    """The provenance block of a pass: ``config`` the scene as the pass ran it (every override applied),
    ``water`` and ``instrument`` (a :class:`muls.instrument.description.Instrument`, its gate as the pass set it) as the model
    used them, ``level`` the fidelity level, ``fingerprint`` its :func:`inputs_fingerprint`."""
    return {
        "muls_scanner_version": __version__,
        "output_format_version": OUTPUT_FORMAT_VERSION,
        "inputs_fingerprint": fingerprint,
        "scene_file": str(config.source_path) if config.source_path else None,
        "overrides": jsonable(dict(sorted(config.overrides.items()))),
        "crs": crs_provenance(config.crs),
        "water": water_provenance(config, water),
        "instrument": jsonable(instrument),
        "fidelity": jsonable(level),
    }


def point_cloud_provenance(block: dict) -> dict:
    """The provenance a point cloud carries: the pass's ``block`` without its inputs fingerprint (which also covers
    files other than the cloud, such as the renders) and without the values given that change no point
    (:data:`POINT_NEUTRAL_KEYS`), so that a seed's cloud has the same bytes whatever the chunk size or the other
    files asked for."""
    overrides = {k: v for k, v in block["overrides"].items() if k not in POINT_NEUTRAL_KEYS}
    return {**{k: v for k, v in block.items() if k != "inputs_fingerprint"}, "overrides": overrides}


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def raster_files(config: SceneConfig) -> list[Path]:
    """The raster files a scene's seabed reads (bathymetry, classes): their bytes are inputs like mesh files'."""
    seabed = config.seabed
    files = [getattr(seabed, "resolved_raster", None)]
    classes = getattr(seabed, "classes", None)
    files += [classes.resolved_raster] if classes is not None else []
    return [f for f in files if f is not None]


def inputs_fingerprint(config: SceneConfig, options, level: FidelityLevel) -> str:
    """SHA-256 (hex) of everything a pass's files follow from: ``config`` (the scene as given, every override
    applied, before the pass derives its gate) as validated, the values given on top of the file, the bytes of
    its mesh files, the water and the instrument as muls resolves them (a preset's values included), the fidelity
    ``level``, the ``options`` (a :class:`~scanner_sim.survey.setup.PassOptions`) that choose the files, and
    :data:`OUTPUT_FORMAT_VERSION`. Where the scene file lies, the progress bar and the software version are left
    out: they change no file."""
    inputs = {
        "output_format_version": OUTPUT_FORMAT_VERSION,
        "scene": config.model_dump(mode="json"),
        "overrides": jsonable(dict(sorted(config.overrides.items()))),
        "meshes": [_file_sha256(o.resolved_path) for o in config.objects
                   if isinstance(o, MeshObject) and o.resolved_path is not None],
        "water": jsonable(config.water_model()),
        "instrument": jsonable(config.instrument_model()),
        "fidelity": jsonable(level),
        "options": {"waveforms": options.waveforms, "render": options.render, "render_size": options.render_size,
                    "write_scene": options.write_scene, "coverage": jsonable(options.coverage)},
    }
    rasters = raster_files(config)
    if rasters:  # only then: the fingerprints of scenes without rasters stay as they were
        inputs["rasters"] = [_file_sha256(path) for path in rasters]
    text = json.dumps(jsonable(inputs), sort_keys=True, ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
