"""Result files: a morph's ``result.json``, ``shapes.npz`` and ``final_shape.csv``
(:func:`save_result`) and a track's ``track.json``, ``track.npz`` and
``strain_segments.csv`` (:func:`save_track`), each file written atomically."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..options import parameters
from ..version import __version__
from .atomic import atomic_write
from .points import write_points

__all__ = ["result_summary", "save_result", "save_track"]


def save_result(morph, out_dir, *, options: dict | None = None,
                inputs: list | None = None) -> None:
    """Write a morph's result into ``out_dir`` (created if needed), one file at a time.

    Three files are written, each atomically (wrap the call in :func:`atomic_output_dir`
    for all or nothing): ``result.json`` (the summary of :func:`result_summary`, strict
    JSON: non-finite numbers as ``null``); ``shapes.npz``, arrays ``shapes`` (T+1, m, d),
    ``loads`` (T+1, m, d), ``node_energy`` (T+1, m), ``energy`` (T+1,),
    ``mean_distance`` (T+1,) and ``pairs`` (K, 2), int: source and target node indices of
    each match; ``final_shape.csv``, the last shape ``shapes[-1]`` with a header
    ``x,y[,z]``.

    Parameters
    ----------
    morph : Morph
    out_dir : str or os.PathLike
    options : dict, optional
        Every option of the run by flat name, as given (the command line's record).
    inputs : list of dict, optional
        The input files, ``{"path", "sha256"}`` each.

    Raises
    ------
    OptionError
        If ``options`` hold a value that cannot be written as JSON.
    """
    out_dir = Path(out_dir)
    summary = result_summary(morph, options=options, inputs=inputs)
    try:
        text = json.dumps(summary, indent=2, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"options cannot be written as JSON: {exc}") from None
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_write(out_dir / "result.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    with atomic_write(out_dir / "shapes.npz") as tmp:
        np.savez_compressed(
            tmp, shapes=shapes, loads=np.asarray(morph.loads, dtype=np.float64),
            node_energy=np.asarray(morph.node_energy, dtype=np.float64),
            energy=np.asarray(morph.energy, dtype=np.float64),
            mean_distance=np.asarray(morph.mean_distance, dtype=np.float64),
            pairs=_pairs_array(morph), **_contours(morph.source))
    write_points(out_dir / "final_shape.csv", shapes[-1],
                 contours=getattr(morph.source, "contours", None),
                 frame=getattr(morph.target, "frame", None))  # the shapes' frame


def _contours(source) -> dict:
    """``{"contours": node counts}`` for a source of several contours, else nothing."""
    contours = getattr(source, "contours", None)
    return {"contours": np.array(contours, dtype=np.int64)} if contours else {}


def result_summary(morph, *, options: dict | None = None, inputs: list | None = None) -> dict:
    """The content of ``result.json``.

    Its fields::

        {
          "modalmorph_version": str,      # the library that wrote it
          "inputs": [{"path", "sha256"}], # the input files (empty when not given)
          "options": {...},               # every option as given, by flat name
          "parameters": {...},            # what the run used (options.parameters)
          "converged": bool,              # the distance reached the tolerance
          "stop_reason": str,             # tolerance, equilibrium or max_steps
          "message": str,                 # the same in one sentence, with units
          "distance": float,              # the stop test's measure at the end
          "tolerance": float,             # its tolerance (input units)
          "steps": int,                   # T, the number of time steps taken
          "matches": int,                 # K, the number of matched node pairs
          "source_nodes": int,            # m
          "target_nodes": int,            # n
          "dim": int,                     # 2 or 3
          "mean_distance": [float, ...],  # T + 1 values, per step (step 0 = source)
          "energy": [float, ...],         # T + 1 values, strain energy per step
          "self_intersections": [int, ...] or null, # per step: surfaces, faces cutting
                                   # another; 2D contours, folds (pairs of segments that
                                   # cross, tracing noise's tiny loops left out);
                                   # null: not checked (point sets, no pymeshlab)
          "similarity": {...} or null,   # removed first (remove_rigid), Horn's of the pairs
          "co_rotation": {...} or null,  # taken along the steps (a turn over CO_ROTATE)
          "mirror": float or null        # the target looks like the source's mirror image:
                                         # how much better the source reflected fits
        }  # a similarity: {"angle": degrees, "scale", "rotation": d x d, "translation"}
    """
    return {
        "modalmorph_version": __version__,
        "inputs": list(inputs or []),
        "options": dict(options or {}),
        "parameters": parameters(morph),
        "converged": bool(morph.converged),
        "stop_reason": morph.stop_reason,
        "message": morph.message,
        "distance": float(morph.distance),
        "tolerance": float(morph.tolerance),
        "steps": int(morph.steps),
        "matches": len(_pairs_array(morph)),
        "source_nodes": int(morph.source.m),
        "target_nodes": int(morph.target.m),
        "dim": int(morph.source.dim),
        "mean_distance": _finite_or_none(morph.mean_distance),
        "energy": _finite_or_none(morph.energy),
        "self_intersections": _counts_or_none(getattr(morph, "self_intersections", None)),
        "similarity": _similarity_or_none(getattr(morph, "similarity", None)),
        "co_rotation": _similarity_or_none(getattr(morph, "co_rotation", None)),
        "mirror": getattr(getattr(morph, "matching", None), "mirror", None),
    }


def _similarity_or_none(similarity) -> dict | None:
    if similarity is None:
        return None
    return {"angle": similarity.angle, "scale": float(similarity.scale),
            "rotation": np.asarray(similarity.rotation).tolist(),
            "translation": np.asarray(similarity.translation).tolist()}


def _pairs_array(morph) -> np.ndarray:
    return morph.matching.pairs


def _counts_or_none(counts) -> list | None:
    return None if counts is None else [int(c) for c in counts]


def _finite_or_none(values) -> list:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _json_default(obj):
    if isinstance(obj, np.generic):
        value = obj.item()
        return None if isinstance(value, float) and not math.isfinite(value) else value
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"{type(obj).__name__} {obj!r} is not JSON serializable")


def save_track(track, out_dir, *, options: dict | None = None,
               input_files: list | None = None) -> None:
    """Write a :class:`modalmorph.Track` into ``out_dir``, one file at a time (wrap the
    call in :func:`atomic_output_dir` for all or nothing).

    The energies are those of :class:`modalmorph.Track`: ``energy`` of frame ``f``'s
    morph from the tracked frame ``source_frame`` (frame 0 with ``reference="first"``,
    ``f - 1`` with ``"previous"``), ``cumulative_energy`` summed over the morphs that
    lead from frame 0 to frame ``f`` (with ``"first"`` the one morph from frame 0).

    ``track.npz``
        Arrays ``points`` (F, m, d) (the trajectories), ``source_frame``, ``energy``,
        ``cumulative_energy``, ``strain``, ``distance`` (F,), ``node_energy`` (F, m),
        ``edges`` (e, 2),
        ``edge_strain`` (F, e), ``segment_strain`` (F, S), ``segment_of_edge`` (e,),
        ``crossed``, ``slide``, ``slid`` (F,).
    ``track.json``
        ``modalmorph_version``, ``parameters``, ``inputs`` (frame names), ``nodes``,
        ``input_files`` (each file's ``path`` and ``sha256``, when given), ``options``
        (every option of the run by flat name, when given), ``nodes``,
        ``dim``, ``closure_error`` (or null) and ``frames``: per frame ``name``,
        ``observed_nodes``, ``source_frame``, ``steps``, ``converged``, ``energy``,
        ``cumulative_energy``,
        ``strain``, ``segment_strain``, ``distance``, ``crossed``, ``slide`` (null where
        not measured), ``slid`` (frame 0: no morph, ``steps`` 0).
    ``strain_segments.csv``
        One row per frame: ``frame,global,segment_1,...,segment_S``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    frames = []
    for f in range(track.n_frames):
        run = track.morphs[f - 1] if f else None
        frames.append({
            "name": track.names[f], "observed_nodes": int(track.frames[f].m),
            "source_frame": int(track.source_frame[f]),
            "steps": run.steps if run else 0, "converged": bool(run.converged) if run else True,
            "energy": float(track.energy[f]),
            "cumulative_energy": float(track.cumulative_energy[f]),
            "strain": float(track.strain[f]),
            "segment_strain": _finite_or_none(track.segment_strain[f]),
            "distance": float(track.distance[f]), "crossed": bool(track.crossed[f]),
            "slide": _finite_or_none([track.slide[f]])[0], "slid": bool(track.slid[f])})
    summary = {"modalmorph_version": __version__, "parameters": track.params,
               "inputs": list(track.names), "input_files": list(input_files or []),
               "options": dict(options or {}), "nodes": int(track.points.shape[1]),
               "dim": int(track.points.shape[2]), "closure_error": track.closure_error,
               "frames": frames}
    text = json.dumps(summary, indent=2, default=_json_default, allow_nan=False)
    with atomic_write(out_dir / "track.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    with atomic_write(out_dir / "track.npz") as tmp:
        np.savez_compressed(
            tmp, points=track.points, source_frame=track.source_frame,
            energy=track.energy, node_energy=track.node_energy,
            cumulative_energy=track.cumulative_energy, strain=track.strain,
            distance=track.distance, edges=track.edges, edge_strain=track.edge_strain,
            segment_strain=track.segment_strain, segment_of_edge=track.segment_of_edge,
            crossed=track.crossed, slide=track.slide, slid=track.slid,
            **_contours(track.frames[0]))
    n_seg = track.segment_strain.shape[1]
    table = np.column_stack([np.arange(track.n_frames), track.strain, track.segment_strain])
    header = ",".join(["frame", "global", *[f"segment_{s + 1}" for s in range(n_seg)]])
    with atomic_write(out_dir / "strain_segments.csv") as tmp:
        np.savetxt(tmp, table, delimiter=",", header=header, comments="",
                   fmt=["%d"] + ["%.6g"] * (1 + n_seg))
