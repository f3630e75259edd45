"""Labelled datasets (docs/datasets.md): N scenes drawn from a spec (:mod:`.dataset_spec`, :mod:`.dataset_draw`),
run as passes on the campaign machinery (:func:`~scanner_sim.runs.jobs.run_jobs`, Dask or this process), and a
manifest of every scene's drawn values, seeds, objects, split and class counts.

Scenes are drawn as they run, never all at once: a dataset of a million scenes starts its first pass at once and
holds a few scenes in memory (:class:`DrawnScenes`). Before the folder is touched, the first
:data:`CHECKED_FIRST` scenes are drawn (a drawn value the scene format refuses names its scene) and the first one's
set-up is checked; every later scene is drawn, and its set-up checked, in the batch it runs in, so a refusal there
ends the run (exit 2) with the scenes before it complete.

The folder ``--out DIR`` is locked while the dataset runs (:func:`~scanner_sim.io.run_dir.hold_output`). Its
``spec.json`` (the spec as checked) is written first and ``manifest.json`` last, so a folder with a manifest holds
the whole dataset. A run into a folder that holds the same spec, or the same with fewer scenes, resumes it: the
manifest is removed first, complete scenes are kept and the others run. A folder holding another spec, or other
files, is refused.
"""

from __future__ import annotations

import contextlib
import functools
import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.config.materials import CLASS_NAMES
from scanner_sim.io.run_dir import hold_output
from scanner_sim.runs.campaign import load_base_scene
from scanner_sim.runs.dataset_draw import SPLITS, DrawnScene, draw_scene, scene_folder
from scanner_sim.runs.dataset_spec import DatasetSpec, parse_dataset_spec, read_spec_data
from scanner_sim.runs.jobs import check_jobs, completed_summary, run_jobs
from scanner_sim.runs.tasks import DEFAULT_RETRIES, PassJob
from scanner_sim.survey.setup import PassOptions

__all__ = ["MANIFEST", "SCENES_DIR", "SPEC_RECORD", "Dataset", "class_counts", "load_dataset", "parse_dataset",
           "run_dataset"]

#: The files of a dataset folder: the spec as checked (first), the scenes' folder, the manifest (last).
SPEC_RECORD, SCENES_DIR, MANIFEST = "spec.json", "scenes", "manifest.json"
#: Class name -> LAS classification code (the scene labels and noise).
CLASS_CODES = {name: code for code, name in sorted(CLASS_NAMES.items())}
#: Version of the manifest's layout.
MANIFEST_VERSION = 1
#: Scenes drawn (and so validated) before the output folder is touched; later ones are drawn as they run. Drawing
#: takes about 10 ms a scene, checking a set-up (building the scene) about a second, so drawing every scene first
#: took hours for a million (and all their memory).
CHECKED_FIRST = 32
#: Scenes in flight per worker: each batch is drawn, its set-ups checked, and run; a few per worker keep the workers
#: busy between batches while memory holds only the batch.
SCENES_PER_WORKER = 4


class DrawnScenes(Sequence):
    """A dataset's scenes in index order, each drawn when first asked for (:func:`draw_scene`); the last few kept."""

    def __init__(self, spec: DatasetSpec, base: SceneConfig):
        self.spec, self.base = spec, base
        self._draw = functools.lru_cache(maxsize=256)(lambda index: draw_scene(spec, base, index))

    def __len__(self) -> int:
        return self.spec.scenes

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if not -len(self) <= index < len(self):
            raise IndexError(f"scene {index} of {len(self)}")
        return self._draw(index % len(self))


@dataclass(frozen=True)
class Dataset:
    """A checked spec, its base scene and its scenes, drawn when asked for (:class:`DrawnScenes`, index order)."""

    spec: DatasetSpec
    base: SceneConfig
    scenes: DrawnScenes
    source_path: Path | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    def job(self, scene: DrawnScene) -> PassJob:
        """The pass of ``scene``, into ``scenes/NAME/``."""
        return PassJob(scene.name, scene.config, PassOptions(progress=False, render=self.spec.render))

    def record(self) -> dict:
        """What ``spec.json`` holds: the spec as checked, every default filled in (a rerun compares it)."""
        return {"spec": self.spec.model_dump(mode="json"), "file": str(self.source_path) if self.source_path else None}


def parse_dataset(data: Any, base_dir: Path | None = None, name: str = "dataset",
                  source_path: Path | None = None) -> Dataset:
    """A spec mapping checked, its base scene loaded and its first :data:`CHECKED_FIRST` scenes drawn and validated;
    the others are drawn when asked for."""
    spec = parse_dataset_spec(data, name)
    base = load_base_scene(spec.scene, base_dir)
    scenes = DrawnScenes(spec, base)
    for index in range(min(CHECKED_FIRST, spec.scenes)):
        scenes[index]
    return Dataset(spec, base, scenes, source_path)


def load_dataset(path: str | Path) -> Dataset:
    """Read, check and draw a spec file (see :func:`parse_dataset`)."""
    path = Path(path)
    return parse_dataset(read_spec_data(path), path.parent, path.stem, path)


def class_counts(las_path: Path) -> dict[str, int]:
    """Points per class name (``CLASS_NAMES``; a code without a name by its number) in a LAS file, read in chunks."""
    import laspy

    counts = np.zeros(256, np.int64)
    with laspy.open(las_path) as reader:
        for points in reader.chunk_iterator(1_000_000):
            counts += np.bincount(np.asarray(points.classification), minlength=256)
    return {CLASS_NAMES.get(code, str(code)): int(counts[code]) for code in np.flatnonzero(counts)}


def object_table(scene: DrawnScene) -> list[dict]:
    """The scene's objects with the ``object_id`` their points carry in points.las: the scene's parts are the seabed,
    the rocks (when there are any), then the objects in order (``world.scene.build_scene``)."""
    config = scene.config
    rocks = getattr(config.seabed, "rocks", None)  # a raster seabed has none
    first = 0 if config.seabed is None else 1 + bool(rocks and rocks.count)
    table = []
    if config.seabed is not None:
        table.append({"object_id": 0, "name": "seabed", "type": "seabed", "class": config.seabed.label})
        if rocks and rocks.count:
            table.append({"object_id": 1, "name": "rocks", "type": "rocks", "class": rocks.label, "count": rocks.count})
    for k, obj in enumerate(config.objects):
        table.append({"object_id": first + k, "name": obj.name, "type": obj.type, "class": obj.label})
    return table


def _check_folder(out: Path, record: dict) -> None:
    """Refuse a folder that holds anything but this spec's dataset (complete or not), or the same spec with fewer
    scenes named alike (a dataset grows: its scenes stay what they were)."""
    if not out.exists():
        return
    if not out.is_dir():
        raise ValueError(f"--out {str(out)!r}: a file, not a folder")
    held = sorted(p.name for p in out.iterdir())
    if not held:
        return
    try:
        earlier = json.loads((out / SPEC_RECORD).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise ValueError(f"--out {str(out)!r}: holds {', '.join(held[:3])}{', ...' if len(held) > 3 else ''} but no "
                         f"dataset ({SPEC_RECORD}); give an empty or new folder") from None
    old, new = earlier.get("spec") or {}, record["spec"]
    key = next((k for k in new if k != "scenes" and old.get(k) != new[k]), None)
    if key is None and old.get("scenes") != new["scenes"]:
        count = old.get("scenes")
        if isinstance(count, int) and count < new["scenes"] and \
                scene_folder(count - 1, count) == scene_folder(count - 1, new["scenes"]):
            return
        key = "scenes"
    if key is not None:
        raise ValueError(f"--out {str(out)!r}: holds the dataset of another spec ({key} = {old.get(key)!r} there, "
                         f"{new.get(key)!r} here; a dataset may only grow); give another folder, or remove it to "
                         "start again")


def run_dataset(dataset: Dataset, out_dir: str | Path, client=None, *, retries: int = DEFAULT_RETRIES,
                redo: bool = False, progress: bool = True) -> dict:
    """Run every scene of ``dataset`` into ``out_dir/scenes/`` (on ``client``, else in this process) and write the
    manifest; returns it. Its ``failed`` lists the scenes whose pass failed: then no manifest is written (running
    again redoes them). Scenes already complete in the folder are skipped unless ``redo``.

    Scenes are drawn, checked and run in batches (:data:`SCENES_PER_WORKER` a worker; one at a time in this process),
    each scene written as it completes: an interrupted run keeps every complete scene, and the next resumes after
    them."""
    out = Path(out_dir)
    with hold_output(out):
        record = dataset.record()
        _check_folder(out, record)
        total = len(dataset.scenes)
        check_jobs([dataset.job(dataset.scenes[0])], passes=total)  # before the folder changes
        out.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            (out / MANIFEST).unlink()  # an interrupted rerun must not look complete
        io.write_summary_json(out / SPEC_RECORD, record)
        batch = 1 if client is None else SCENES_PER_WORKER * max(1, len(client.scheduler_info()["workers"]))
        entries, failed = [], []
        with tqdm(total=total, unit="scene", disable=not progress, desc="scenes") as bar:
            for start in range(0, total, batch):
                scenes = dataset.scenes[start:start + batch]
                jobs = [dataset.job(scene) for scene in scenes]
                check_jobs([job for job in jobs if redo or completed_summary(out / SCENES_DIR / job.name, job) is None],
                           passes=total)
                outcomes = run_jobs(jobs, out / SCENES_DIR, client, retries=retries, redo=redo, progress=False,
                                    checked=True)
                for scene, outcome in zip(scenes, outcomes):
                    if outcome.status == "failed":
                        failed.append({"scene": outcome.job.name, "error": outcome.error})
                    elif not failed:  # the manifest is written only when every scene is complete
                        entries.append(scene_entry(scene, outcome.summary, out))
                bar.update(len(scenes))
        if failed:
            return {"failed": failed}
        manifest = build_manifest(dataset, entries)
        io.write_summary_json(out / MANIFEST, manifest)
        return manifest


def scene_entry(scene: DrawnScene, summary: dict, out: Path) -> dict:
    """A complete scene's entry in the manifest: its folder, seeds, drawn values, objects, split, points and class
    counts (from its points.las)."""
    counts = class_counts(out / SCENES_DIR / scene.name / "points.las")
    detected = {o["name"]: o["detected"] for o in (summary.get("coverage") or {}).get("objects", [])}
    objects = [row | ({"detected": detected[row["name"]]} if row["name"] in detected else {})
               for row in object_table(scene)]
    return {"index": scene.index, "dir": f"{SCENES_DIR}/{scene.name}", "split": scene.split,
            "seed": scene.seed, "seabed_seed": scene.seabed_seed, "drawn": scene.drawn,
            "water": summary["water"], "pulses": summary["pulses"], "points": summary["points"],
            "classes": counts, "objects": objects}


def build_manifest(dataset: Dataset, scenes: list[dict]) -> dict:
    """The manifest of a complete dataset from its scenes' entries (:func:`scene_entry`, index order): the entries,
    the totals and the splits."""
    totals = Counter()
    for entry in scenes:
        totals.update(entry["classes"])
    spec = dataset.spec
    return {
        "manifest_version": MANIFEST_VERSION,
        "dataset": dataset.name,
        "spec_file": str(dataset.source_path) if dataset.source_path else None,
        "base_scene": dataset.base.name,
        "seed": spec.seed,
        "scene_count": len(scenes),
        "points": sum(s["points"] for s in scenes),
        "classes": dict(sorted(totals.items(), key=lambda item: CLASS_CODES.get(item[0], 256))),
        "class_codes": CLASS_CODES,
        "split_rule": "u = int.from_bytes(sha256(f'{seed}:{index}').digest()[:8], 'big') / 2**64; train if "
                      "u < train, validation if u < train + validation, else test",
        "split_fractions": spec.splits.model_dump(),
        "splits": {name: [s["dir"] for s in scenes if s["split"] == name] for name in SPLITS},
        "scenes": scenes,
    }


def summary_line(manifest: dict) -> dict:
    """What ``scanner-sim dataset --json`` prints: scenes, points, classes and the scenes per split."""
    return {"scenes": manifest["scene_count"], "points": manifest["points"], "classes": manifest["classes"],
            "splits": {name: len(dirs) for name, dirs in manifest["splits"].items()}}
