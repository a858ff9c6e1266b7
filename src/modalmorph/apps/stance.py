"""``modalmorph stance``: every loaded part of a pressure stack followed through the
stance phase (:func:`modalmorph.stance`), written to a folder.

The input is an NPY/NPZ pressure array, (T, H, W) or (H, W), or ``jiku:SUBJECT:TRIAL``
(a stance phase of the optional package jiku-data, at its 500 Hz; ``--every 20`` takes
25 Hz). ``modalmorph track`` on one NPY/NPZ stack of pressures (more than two levels:
not a stack of masks) runs this too (:func:`is_pressure_stack`), so the forefoot and
the toes are followed with the heel; stacks of masks and contour files are tracked as
before. The folder holds ``result.json`` (options, level, events, per part its frames
and how it began and ended, :func:`stance_summary`), ``stance.csv`` (a row per part
and frame: sensors, area, energy, fit), ``parts.npz`` (``part_<k>``: tracked nodes
(F_p, m, 2), ``frames_<k>``) and the figures ``stance.png`` and ``stance_energy.png``.
"""

from __future__ import annotations

import csv
import json
import logging
import sys
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..figures.stance import length_unit, plot_footprints, save_stance_figures
from ..io import atomic_output_dir
from ..io.pressure import jiku_conditions, jiku_peaks, jiku_trial, read_pressure
from ..options import StanceOptions, split
from ..pedobarography import OTHER_FOOT, register_footprints, stance

__all__ = ["add_parser", "is_pressure_stack", "run", "run_footprints", "stance_files",
           "stance_summary", "track_stack", "write_footprints", "write_stance"]

log = logging.getLogger(__name__)
_JIKU = "jiku:"
_SPEEDS = {1: "slow", 2: "normal", 3: "fast"}  # jiku-data's speed conditions


def add_parser(command, add_option_flags, add_config, load_config) -> None:
    """Register ``stance`` with the command line's ``command(name, run, help, text)``,
    its option flags, ``--config`` and the config's reader."""
    p = command("stance", run, "every loaded part of a pressure stack through the stance "
                "phase", "Follow every loaded part of a foot on a pressure plate (heel, "
                "forefoot, toes) from when it appears to when it leaves, through merges; "
                "write the tracked contours, strain energy per part and in all, and "
                "figures over the pressure images.")
    p.add_argument("input", metavar="INPUT",
                   help="an NPY/NPZ pressure array (T, H, W) or (H, W), or jiku:SUBJECT:"
                        "TRIAL (needs the optional package jiku-data)")
    q = command("footprints", run_footprints, "peak-pressure images registered to a "
                "template footprint", "Register peak-pressure images part by part (heel, "
                "forefoot, toes) to a template footprint; write a row per image (area, "
                "strain energy, where it peaks) and a grid of the registered footprints "
                "coloured by energy.")
    q.add_argument("input", metavar="INPUT",
                   help="an NPY/NPZ array of peak images (N, H, W), or jiku:SUBJECT (its 60 "
                        "trials; needs the optional package jiku-data)")
    q.add_argument("--template", default=None,
                   help="the most typical image (default), mean, or an image number")
    for parser in (p, q):
        parser.add_argument("-o", "--out", type=Path, required=True,
                            help="output folder (replaced as a whole)")
        add_config(parser)
        add_option_flags(parser, (StanceOptions,))
        parser.set_defaults(load_config=load_config)


def is_pressure_stack(paths) -> bool:
    """Whether ``modalmorph track`` was given one NPY/NPZ (T, H, W) array of more than
    two levels (pressures, not masks or points)."""
    if len(paths) != 1 or Path(paths[0]).suffix.lower() not in (".npy", ".npz"):
        return False
    try:
        array = read_pressure(paths[0])
    except ValueError:
        return False  # not a pressure stack: the track readers say what it is
    return array.shape[0] > 1 and array.shape[-1] not in (2, 3) and \
        len(np.unique(array)) > 2


def _options(args) -> StanceOptions:
    """Options from ``--config`` and the flags (the command line wins)."""
    values = {} if args.config is None else args.load_config(args.config)
    for name in StanceOptions.__dataclass_fields__:
        if getattr(args, name, None) is not None:
            values[name] = getattr(args, name)
    return split(values, (StanceOptions,), where="options")[StanceOptions]


def run(args) -> int:
    """The ``stance`` command: :func:`stance_files`."""
    return stance_files(args.input, args.out, _options(args), quiet=args.quiet)


def run_footprints(args) -> int:
    """The ``footprints`` command: read, register, write a table, a record, a figure."""
    name, opts = str(args.input), _options(args)
    template = args.template if args.template in (None, "mean") else _number(args.template)
    columns = {}
    if name.startswith(_JIKU):
        subject = int(name[len(_JIKU):])
        images = jiku_peaks(subject)
        columns["condition"], columns["speed_m_s"] = jiku_conditions(subject)
    else:
        images = read_pressure(args.input)
    if template is not None and template != "mean" and not 0 <= template < len(images):
        raise OptionError(f"template must be mean or an image number 0..{len(images) - 1}, "
                          f"got {args.template!r}")
    regs = register_footprints(images, template=template, options=opts)
    with atomic_output_dir(args.out) as tmp:
        write_footprints(regs, Path(tmp), columns, dict(input=name, template=template,
                                                        options=opts.record()))
    if not args.quiet:
        energy = np.array([r.energy for r in regs])
        other = sum(r.other_foot > OTHER_FOOT for r in regs)
        print(f"{len(regs)} images registered; strain energy median {np.median(energy):.4g}"
              f", {sum(bool(r.missing) for r in regs)} with a template part unpaired"
              + (f", {other} that look like the other foot" if other else ""),
              file=sys.stderr)
    return 0


def _number(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise OptionError(f"template must be mean or an image number, got {text!r}") from None


def write_footprints(regs, folder: Path, columns: dict, record: dict, *,
                     figure: bool = True) -> None:
    """Write ``result.json`` (``record`` and the template's parts), ``footprints.csv`` (a
    row per image, with the per-image ``columns``) and, with ``figure``,
    ``footprints.png``."""
    from matplotlib.figure import Figure

    n_parts = len(regs[0].template)
    (folder / "result.json").write_text(json.dumps(
        {**record, "template_parts": [t.tolist() for t in regs[0].template]}, indent=1))
    with open(folder / "footprints.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["image", *columns, "area_mm2", "energy",
                         *(f"energy_part_{k}" for k in range(n_parts)), "peak_part",
                         "peak_x_mm", "peak_y_mm", "unpaired_parts", "other_foot"])
        for i, r in enumerate(regs):
            writer.writerow([i, *(v[i] for v in columns.values()), f"{r.area:.6g}",
                             f"{r.energy:.6g}", *(f"{e:.6g}" for e in r.part_energy),
                             r.peak_part, f"{r.peak[0]:.4g}", f"{r.peak[1]:.4g}",
                             " ".join(map(str, r.missing)), f"{r.other_foot:.3g}"])
    if not figure:
        return
    fig = Figure(figsize=(min(len(regs), 20) * 0.7 + 1.5, 2.2 * -(-len(regs) // 20) + 0.3),
                 layout="constrained")
    said = columns.get("speed", [_SPEEDS.get(int(c), c) for c in columns.get("condition", ())])
    titles = [f"{i} {said[i]}" if len(said) else f"{i}" for i in range(len(regs))]
    plot_footprints(regs, fig=fig, ncols=20, titles=titles,
                    unit="mm" if record["options"]["pixel_size"] != 1 else "sensors")
    fig.savefig(folder / "footprints.png", dpi=120)


def stance_files(source, out, options: StanceOptions, *, quiet: bool = False) -> int:
    """Read, follow, write; prints a summary line unless ``quiet``."""
    name = str(source)
    if name.startswith(_JIKU):
        subject, trial = (int(v) for v in name[len(_JIKU):].split(":"))
        pressure = jiku_trial(subject, trial)
    else:
        pressure = read_pressure(source)
    result = stance(pressure, options=options, name=name)
    with atomic_output_dir(out) as tmp:
        write_stance(result, Path(tmp), name)
        figures = save_stance_figures(result, tmp)
    if not quiet:
        fit = max(float(p.node_distance.max()) for p in result.parts)
        print(f"{result.n_frames} frames, {len(result.parts)} parts; total strain energy "
              f"{float(result.energy.sum()):.4g}; largest node-to-boundary distance "
              f"{fit:.3g} {length_unit(result.params['pixel_size'])}", file=sys.stderr)
        for path in ["result.json", "stance.csv", "parts.npz", *(f.name for f in figures)]:
            print(f"  {Path(out) / path}", file=sys.stderr)
    return 0


def stance_summary(result) -> dict:
    """One stance phase in numbers: the largest loaded area (all parts, mm^2), the total
    strain energy, where the energy peaks (the centroid of the part and frame of the
    largest part energy, mm) and the largest node-to-boundary distance (mm)."""
    areas = np.zeros(result.n_frames)
    for p in result.parts:
        areas[p.frames] += p.area
    top = max(result.parts, key=lambda p: float(p.energy.max()))
    peak = top.points[int(np.argmax(top.energy))].mean(axis=0)
    return dict(area_mm2=float(areas.max()), energy=float(result.energy.sum()),
                peak_x_mm=float(peak[0]), peak_y_mm=float(peak[1]),
                node_distance_mm=max(float(p.node_distance.max()) for p in result.parts))


def write_stance(result, folder: Path, name: str, extra: dict | None = None) -> None:
    """Write ``result.json`` (with :func:`stance_summary`; ``extra`` over it), ``stance.csv``
    and ``parts.npz`` of a :class:`~modalmorph.Stance` into ``folder``."""
    parts = [dict(part=p.part, frames=(result.frames[p.frames]).tolist(), nodes=int(
        p.points.shape[1]), start=p.start, end=p.end) for p in result.parts]
    record = dict(input=name, level=result.level, pixel_size=result.pixel_size,
                  frames=result.frames.tolist(), options=result.params,
                  events=list(result.events), parts=parts,
                  energy=result.energy.tolist(), summary=stance_summary(result))
    record.update(extra or {})
    (folder / "result.json").write_text(json.dumps(record, indent=1))
    with open(folder / "stance.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["frame", "part", "sensors", "area_mm2", "energy",
                         "node_distance_mm", "boundary_gap_mm", "crossed"])
        for p in result.parts:
            for k, f in enumerate(p.frames):
                writer.writerow([int(result.frames[f]), p.part, int(p.sensors[k]),
                                 f"{p.area[k]:.6g}", f"{p.energy[k]:.6g}",
                                 f"{p.node_distance[k]:.4g}", f"{p.boundary_gap[k]:.4g}",
                                 int(p.crossed[k])])
    np.savez_compressed(folder / "parts.npz", **{
        **{f"part_{p.part}": p.points for p in result.parts},
        **{f"frames_{p.part}": result.frames[p.frames] for p in result.parts}})


def track_stack(args) -> int:
    """``modalmorph track`` on one pressure stack: :func:`stance_files` with its
    ``--threshold`` (the other track options do not apply), said."""
    log.info("%s: a pressure stack: every loaded part is followed, as modalmorph stance "
             "does", args.inputs[0])
    values = {} if args.threshold is None else {"threshold": args.threshold}
    opts = split(values, (StanceOptions,), where="options")[StanceOptions]
    return stance_files(args.inputs[0], args.out, opts, quiet=args.quiet)
