"""``modalmorph strain FRAMES... --out DIR``: myocardial strain from segmented frames.

Writes, as one folder (replaced whole or not at all): ``strain.csv`` (``frame, segment,
radial, circumferential, circumferential_endo, circumferential_epi`` in percent, then the
strain rates), ``strain.json`` (definitions, units, reference frame and angle, peaks,
options, inputs with SHA-256), the figures (``strain_curves.png``, ``bullseye.png``,
``wall.png``) and with ``--html`` ``report.html`` (the figures and the peak table in one
self-contained page).
"""

from __future__ import annotations

import argparse
import base64
import html
import json
import sys
from pathlib import Path

import numpy as np

from ..cardiac import DEFINITIONS, KINDS, strain
from ..io import atomic_output_dir
from ..options import MatchOptions, MorphOptions, StrainOptions, flat_fields, split
from ..version import __version__
from .runs import input_records

__all__ = ["register", "run_strain", "write_strain", "STRAIN_CLASSES"]

STRAIN_CLASSES = (StrainOptions, MatchOptions, MorphOptions)
FIGURES = ("strain_curves.png", "bullseye.png", "wall.png")
DPI = 150


def register(command, add_option_flags) -> None:
    """Add the ``strain`` command: ``command(name, run, help, description)`` makes the
    sub-parser, ``add_option_flags(parser, classes)`` its option flags."""
    p = command("strain", run_strain, "radial and circumferential strain of the myocardium",
                "Track the endocardium and epicardium of myocardium masks through the "
                "frames and write Lagrangian radial and circumferential strain per "
                "segment (percent), strain rates, peaks, figures and an HTML report.")
    p.add_argument("inputs", nargs="+", type=Path, metavar="FRAMES",
                   help="myocardium masks: PNG/TIFF files or a folder of them, a "
                        "multi-page TIFF or animated GIF, an (F, H, W) NPY/NPZ stack, a "
                        "NIfTI 2D+t image")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output folder (replaced as a whole)")
    p.add_argument("--html", action="store_true", help="also report.html")
    p.add_argument("--figures", action=argparse.BooleanOptionalAction, default=True,
                   help="the PNG figures (default: yes)")
    add_option_flags(p, STRAIN_CLASSES)


def run_strain(args) -> int:
    """Read, measure, write; one summary line on stderr unless ``-q``."""
    values = {name: " ".join(v) if isinstance(v, list) else v
              for name, _cls, _f in flat_fields(STRAIN_CLASSES)
              if (v := getattr(args, name, None)) is not None}
    objects = split(values, STRAIN_CLASSES)
    inputs = [str(p) for p in args.inputs]
    result = strain(inputs[0] if len(inputs) == 1 else inputs,
                    options=objects[StrainOptions],
                    match_options=None if objects[MatchOptions] == MatchOptions() else
                    objects[MatchOptions],
                    morph_options={  # the flags given, over the strain's defaults
                        f.name: getattr(objects[MorphOptions], f.name)
                        for name, cls, f in flat_fields(STRAIN_CLASSES)
                        if cls is MorphOptions and name in values})
    files = write_strain(result, args.out, inputs=args.inputs, figures=args.figures,
                         report=args.html)
    if not args.quiet:
        kind = "circumferential_endo" if result.endo_only else "circumferential"
        peak, frame = result.peak(kind)
        extra = "" if result.endo_only else (
            f", radial {result.peak('radial')[0][0]:+.1f} % at frame "
            f"{result.peak('radial')[1][0]}")
        print(f"{result.n_frames} frames; peak global {kind.replace('_', ' ')} "
              f"{peak[0]:+.1f} % at frame {frame[0]}{extra}", file=sys.stderr)
        for path in files:
            print(f"  {path}", file=sys.stderr)
    return 0


def write_strain(result, out, *, inputs=(), figures: bool = True,
                 report: bool = False) -> list:
    """Write the folder ``out`` (module docstring); returns the files written."""
    out = Path(out)
    with atomic_output_dir(out) as tmp:
        tmp = Path(tmp)
        np.savetxt(tmp / "strain.csv", _table(result), delimiter=",", fmt="%.6g",
                   header=",".join(_columns(result)), comments="")
        (tmp / "strain.json").write_text(json.dumps(_record(result, inputs), indent=1,
                                                    allow_nan=False), encoding="utf-8")
        if figures or report:
            _figures(result, tmp)
        if report:
            (tmp / "report.html").write_text(_page(result, tmp), encoding="utf-8")
        if report and not figures:  # drawn for the page only
            for name in FIGURES:
                (tmp / name).unlink()
        names = sorted(p.name for p in tmp.iterdir())
    return [out / name for name in names]


def _columns(result) -> list:
    return ["frame", "segment", *KINDS, *(f"{k}_rate" for k in KINDS)]


def _table(result) -> np.ndarray:
    """One row per frame and segment (0 = global): strains, then rates."""
    n_f, n_s = result.n_frames, result.segments + 1
    frame, segment = np.meshgrid(np.arange(n_f), np.arange(n_s), indexing="ij")
    cols = [getattr(result, k) for k in KINDS] + [result.rate(k) for k in KINDS]
    return np.column_stack([frame.ravel(), segment.ravel(), *[c.ravel() for c in cols]])


def _finite(values):
    return [None if not np.isfinite(v) else float(v) for v in np.ravel(values)]


def _record(result, inputs) -> dict:
    per = "per second" if result.params.get("frame_interval") else "per frame"
    peaks = {}
    for kind in KINDS:
        value, frame = result.peak(kind)
        peaks[kind] = {"value": _finite(value), "frame": [int(f) for f in frame]}
    return {
        "modalmorph": __version__, "definitions": DEFINITIONS,
        "units": {"strain": "percent", "strain_rate": f"percent {per}",
                  "coordinates": "input units (pixels times the pixel spacing)"},
        "frames": list(result.names), "reference_frame": result.reference,
        "reference_angle": result.reference_angle, "segments": result.segments,
        "centre": _finite(result.centre), "peaks": peaks,
        "options": _jsonable(result.params),
        "inputs": input_records([str(p) for p in inputs]) if inputs else [],
    }


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def _figures(result, folder: Path) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..figures.strain import plot_bullseye, plot_strain_curves, plot_wall

    kinds = ("circumferential_endo",) if result.endo_only else ("radial", "circumferential")
    rings = plt.figure(figsize=(4.4 * len(kinds), 4.4), layout="constrained")
    for kind, ax in zip(kinds, rings.subplots(1, len(kinds), squeeze=False,
                                              subplot_kw={"projection": "polar"}).ravel(),
                        strict=True):
        plot_bullseye(result, kind, ax=ax)
    for name, fig in (("strain_curves.png", plot_strain_curves(result)),
                      ("bullseye.png", rings),
                      ("wall.png", plot_wall(result))):
        fig.savefig(folder / name, dpi=DPI)
        plt.close(fig)


def _page(result, folder: Path) -> str:
    """A self-contained page: the peak table and the figures inlined."""
    rows = []
    for kind in KINDS:
        value, frame = result.peak(kind)
        cells = "".join(f"<td>{'' if not np.isfinite(v) else f'{v:+.1f} ({f})'}</td>"
                        for v, f in zip(value, frame, strict=True))
        rows.append(f"<tr><th>{kind.replace('_', ' ')}</th>{cells}</tr>")
    head = "".join(f"<th>{'global' if s == 0 else s}</th>"
                   for s in range(result.segments + 1))
    images = "".join(
        f'<img alt="{name}" src="data:image/png;base64,'
        f'{base64.b64encode((folder / name).read_bytes()).decode()}">' for name in FIGURES)
    defs = "".join(f"<li><b>{html.escape(k)}</b>: {html.escape(v)}</li>"
                   for k, v in DEFINITIONS.items())
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>modalmorph strain"
            f"</title><style>body{{font-family:sans-serif;max-width:70em;margin:auto}}"
            f"td,th{{padding:2px 8px;text-align:right}}img{{max-width:100%}}</style></head>"
            f"<body><h1>Myocardial strain</h1><p>{result.n_frames} frames, reference frame "
            f"{result.reference} ({html.escape(result.names[result.reference])}), segment 1 "
            f"from {result.reference_angle:.1f}&deg;. Peak strain, percent (frame):</p>"
            f"<table><tr><th></th>{head}</tr>{''.join(rows)}</table>{images}"
            f"<h2>Definitions</h2><ul>{defs}</ul></body></html>")
