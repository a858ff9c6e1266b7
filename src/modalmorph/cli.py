"""The ``modalmorph`` command line: ``demo``, ``match``, ``morph``, ``track``, ``batch``
and ``app``.

Exit codes: 0 success, 2 bad input or usage (a one-line message naming the file and the
problem), 1 a run that did not converge when ``--strict`` is given or a batch with a failed
item, 130 a batch interrupted by Ctrl-C.

:func:`morph_files` and :func:`track_files` are what ``morph`` and ``track`` do for one
item (read, compute, write one output folder); :mod:`modalmorph.batch` runs them per item.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .track import CORRESPONDENCES, REFERENCES

__all__ = ["main", "ItemRun", "morph_files", "track_files", "check_options",
           "load_config"]

log = logging.getLogger("modalmorph")

# Options of morph() that the command line and a --config file may set.
_MORPH_OPTIONS = {
    "remove_rigid": bool, "k": float, "dt": float, "alpha": float, "delta": float,
    "damping": (float, list), "c_x": float, "c_v": float, "sigma": float,
    "modes": (int, float, str), "scheme": str, "tol": float, "tol_distance": float,
    "max_steps": int, "equilibrium_tol": float, "unmatched": str, "neighbours": int,
    "rotation": str, "free_motion": str, "loads": str,
}
_OTHER_OPTIONS = {"method": str, "match_sigma": float, "nodes": int, "threshold": float,
                  "material": str, "E": float, "nu": float, "rho": float}


_ROTATION_HELP = ("auto (default): keep the common frame of the two inputs unless another "
                  "pose fits clearly better (shapes turned by more than ~20 degrees are "
                  "found); none: the inputs share one frame (frames of a sequence, "
                  "ED/ES of one slice): never turn; free: any pose, by cost alone")


class UsageError(ValueError):
    """Bad input or usage: reported in one line with exit code 2."""


@dataclass(frozen=True)
class ItemRun:
    """What one ``morph`` or ``track`` run computed, and the files it wrote.

    Attributes
    ----------
    result : Morph or Track
    files : tuple of Path
        The files written, under the output folder.
    """

    result: object
    files: tuple


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help, --version (0) or a usage error (2)
        return int(exc.code or 0)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(message)s")
    from .pipeline import MorphDivergedError

    # Library warnings are collected, not printed as they come: after a successful run each
    # is one line; after an error the error's line is the only one.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            code = args.run(args)
        except Exception as exc:  # noqa: BLE001 - one line, never a traceback
            known = isinstance(exc, ValueError | OSError | ImportError | MorphDivergedError)
            text = " ".join(str(exc).split())
            message = text if known and text else f"{type(exc).__name__}: {text}"
            print(f"modalmorph: error: {message}", file=sys.stderr)
            return 2
    for warning in caught:
        print(f"modalmorph: warning: {' '.join(str(warning.message).split())}",
              file=sys.stderr)
    return code


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="modalmorph",
        description="Estimate, by physical principles, how one shape deforms into another "
                    "(Tavares & Pinho 2005): modal matching, Lagrange's dynamic equilibrium, "
                    "strain energy.")
    parser.add_argument("--version", action="version", version=f"modalmorph {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true",
                        help="print nothing but errors (no progress bar, no file list)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = sub.add_parser("demo", parents=[common],
                          help="run the whole method on bundled real data (heart, hands)",
                          description="Morph the bundled end-diastole heart contour into "
                                      "end-systole, and one bundled hand into another, and "
                                      "write results, figures and animations.")
    demo.add_argument("--out", type=Path, default=Path("modalmorph-demo"),
                      help="output folder (default: ./modalmorph-demo)")
    demo.set_defaults(run=_run_demo)

    match = sub.add_parser("match", parents=[common], help="node correspondences only",
                           description="Find correspondences between the nodes of two "
                                       "shapes by modal matching.")
    _add_inputs(match)
    match.add_argument("--method", choices=("auto", "local", "global"), default=None,
                       help="auto (default): the most accurate, order-preserving for "
                            "contours; local: the paper's mutual best; global: an "
                            "assignment over all nodes with implausible pairs rejected")
    match.add_argument("--rotation", choices=("auto", "free", "none"), default=None,
                       help=_ROTATION_HELP)
    match.add_argument("--sigma", type=float, default=None,
                       help="Gaussian width of the matching models in units of the mean "
                            "node spacing (default: 2, or less where that would make the "
                            "Gram matrix ill-conditioned)")
    match.add_argument("--out", type=Path, default=None,
                       help="CSV file for the pairs (source,target,cost); default: stdout")
    match.add_argument("--plot", type=Path, default=None,
                       help="also draw the matches into this image (PNG, SVG, PDF)")
    match.set_defaults(run=_run_match)

    morph = sub.add_parser("morph", parents=[common],
                           help="intermediate shapes, loads and strain energy",
                           description="Match two shapes, integrate Lagrange's dynamic "
                                       "equilibrium to get the intermediate shapes, and "
                                       "write results, figures and an animation.")
    _add_inputs(morph)
    morph.add_argument("--out", type=Path, required=True, help="output folder")
    _add_morph_options(morph)
    o = morph.add_argument_group("outputs")
    o.add_argument("--no-figures", dest="figures", action="store_false",
                   help="skip the PNG/SVG figures")
    o.add_argument("--no-gif", dest="gif", action="store_false", help="skip the GIF")
    o.add_argument("--mp4", action="store_true", help="also write an MP4 (needs ffmpeg)")
    o.add_argument("--vtk", action="store_true",
                   help="also write a VTK time series (.vtu + .pvd) for ParaView")
    o.add_argument("--strict", action="store_true",
                   help="exit with code 1 when the morph does not reach the tolerance")
    o.add_argument("--html", action="store_true",
                   help="also write report.html: the interactive viewer of the result in "
                        "one self-contained file (no network, no server)")
    morph.set_defaults(run=_run_morph)

    track = sub.add_parser("track", parents=[common],
                           help="follow the nodes of the first frame through a sequence",
                           description="Follow the nodes of the first frame through a "
                                       "sequence by morphing the tracked shape onto each "
                                       "next frame; write trajectories, strain energy and "
                                       "contour strain per frame, figures and an animation.")
    track.add_argument("inputs", nargs="+", type=Path, metavar="INPUTS",
                       help="the frames: several files, or one folder or glob pattern of "
                            "images or CSVs (natural order), a multi-page TIFF, an (F, H, W) "
                            "NPY stack of masks, an NPZ with an (F, n, d) array, or a CSV "
                            "with a frame column")
    track.add_argument("--nodes", type=int, default=None,
                       help="resample 2D contours to this many nodes (default: as in the "
                            "file; 200 for images)")
    track.add_argument("--threshold", type=float, default=None,
                       help="grey images: level separating object from background")
    track.add_argument("--out", type=Path, required=True, help="output folder")
    _add_morph_options(track)
    t = track.add_argument_group("sequence")
    t.add_argument("--reference", choices=REFERENCES, default="previous",
                   help="previous (default): morph each tracked frame onto the next; "
                        "first: morph frame 0 straight onto every frame")
    t.add_argument("--correspondence", choices=CORRESPONDENCES, default="nearest",
                   help="nearest (default): pairs in the images' common frame, for "
                        "consecutive frames; modal: modal matching, for large motions")
    t.add_argument("--cycle", action="store_true",
                   help="periodic sequence (a cardiac cycle): also morph the last frame "
                        "back onto the first and report the closure error")
    t.add_argument("--segments", type=int, default=6,
                   help="segments of equal arc length for the strain table (default 6)")
    t.add_argument("--start-node", dest="start_node", type=int, default=0,
                   help="node of the first frame where segment 1 starts (default 0)")
    o = track.add_argument_group("outputs")
    o.add_argument("--no-figures", dest="figures", action="store_false",
                   help="skip the PNG figures")
    o.add_argument("--no-gif", dest="gif", action="store_false", help="skip the GIF")
    track.set_defaults(run=_run_track)

    batch = sub.add_parser("batch", parents=[common],
                           help="many pairs and sequences, on this machine or a Dask cluster",
                           description="Run morph (source,target pairs) and track (frames) "
                                       "for every item of a manifest, each into OUT/<id>/ "
                                       "exactly as the single commands write it, and write "
                                       "OUT/summary.csv. Items already complete in OUT are "
                                       "skipped; a failing item is recorded and the batch "
                                       "goes on. Exit code 1 when an item failed.")
    batch.add_argument("manifest", type=Path, metavar="MANIFEST",
                       help="CSV (columns id, source, target or frames, and any option "
                            "below with underscores; cells are TOML values) or TOML "
                            "([[item]] tables with the same keys); paths relative to it")
    batch.add_argument("--out", type=Path, required=True, help="output folder")
    batch.add_argument("--workers", type=int, default=None,
                       help="worker processes on this machine (default: one per core)")
    batch.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running Dask scheduler (tcp://host:port): run "
                            "there; inputs and OUT must be reachable by its workers")
    batch.add_argument("--engine", choices=("auto", "dask", "processes"), default="auto",
                       help="auto (default): Dask when installed (modalmorph[dask]), "
                            "else a local process pool")
    batch.add_argument("--figures", choices=("none", "summary", "all"), default="none",
                       help="none (default): results only; summary: also one figure of "
                            "the whole batch (OUT/summary.png); all: every item's figures "
                            "and animation too, as morph and track write them")
    batch.add_argument("--force", action="store_true",
                       help="redo items already complete in OUT")
    batch.add_argument("--nodes", type=int, default=None,
                       help="resample 2D contours to this many nodes (as in morph, track)")
    batch.add_argument("--threshold", type=float, default=None,
                       help="grey images: level separating object from background")
    _add_morph_options(batch)
    batch.set_defaults(run=_run_batch)

    app = sub.add_parser("app", parents=[common], help="the interactive web application",
                         description="Serve the method as a local web page: pick two shapes, "
                                     "set the options, run, and explore the result.")
    app.add_argument("--host", default="127.0.0.1",
                     help="address to listen on (default 127.0.0.1: this machine only)")
    app.add_argument("--port", type=int, default=8765, help="port (default 8765; 0: any)")
    app.add_argument("--open", action="store_true", help="open the page in a browser")
    app.set_defaults(run=_run_app)
    return parser


def _add_morph_options(parser):
    """The options of morph() (config file, matching, physics, loads, stopping)."""
    parser.add_argument("--config", type=Path, default=None,
                       help="TOML file of options (same names as below, with underscores: "
                            "k = 50, remove_rigid = true, damping = [0.5, 1.0], ...); "
                            "options given on the command line win")
    parser.add_argument("--method", choices=("auto", "local", "global"), default=None,
                       help="matching method (see 'modalmorph match --help')")
    parser.add_argument("--rotation", choices=("auto", "free", "none"), default=None,
                       help=_ROTATION_HELP)
    parser.add_argument("--match-sigma", dest="match_sigma", type=float, default=None,
                       help="Gaussian width of the matching models (see 'modalmorph match "
                            "--help')")
    g = parser.add_argument_group("physics")
    g.add_argument("--material", default=None,
                   help="preset filling the objects: polyethylene (default, the paper's), "
                        "rubber or unit; or give --E, --nu, --rho")
    g.add_argument("--E", type=float, default=None, help="Young's modulus (custom material)")
    g.add_argument("--nu", type=float, default=None, help="Poisson's ratio (custom material)")
    g.add_argument("--rho", type=float, default=None, help="density (custom material)")
    g.add_argument("--sigma", type=float, default=None,
                   help="how far nodes interact in the physical model: Gaussian width in "
                        "units of the mean spacing between nodes (default: 1, or less "
                        "where that would make the Gram matrix ill-conditioned)")
    g.add_argument("--modes", default=None,
                   help="modes used: 'all' (default), a count (e.g. 40) or a fraction "
                        "(e.g. 2/3 or 0.66); fewer modes are cheaper and less exact")
    g.add_argument("--damping", type=float, nargs="+", metavar="XI", default=None,
                   help="one ratio (default 1): stiffness-proportional damping, every mode "
                        "creeps to the target at nearly one rate (no ripples or folds); or "
                        "two: the ratios at the lowest and highest frequency (the paper "
                        "used 0.005 0.03, which oscillates)")
    g.add_argument("--loads", choices=("consistent", "nodal"), default=None,
                   help="consistent (default): the springs pull every bit of the object in "
                        "proportion to its mass, so all modes move together; nodal: the "
                        "paper's force k (X2 - X) on every node (19)")
    g.add_argument("--free-motion", dest="free_motion", choices=("similarity", "none"),
                   default=None,
                   help="similarity (default): changes of position, orientation and size "
                        "cost no strain energy, so any size ratio is reached; none: the "
                        "paper's U^T K U for every motion")
    d = parser.add_argument_group("loads and time integration")
    d.add_argument("--k", type=float, default=None,
                   help="spring stiffness pulling nodes to their targets, in units of one "
                        "node's own stiffness (default 100): larger pulls harder, needs "
                        "fewer steps and fits closer")
    d.add_argument("--scheme", choices=("implicit", "explicit"), default=None,
                   help="implicit (default): loads at the new shape, always stable; "
                        "explicit: the paper's, loads at the previous shape, diverges "
                        "for large k")
    d.add_argument("--dt", type=float, default=None,
                   help="time step, in units of one node's natural period / 2 pi "
                        "(default 0.1): larger moves further per step")
    d.add_argument("--alpha", type=float, default=None,
                   help="Newmark alpha (default 0.25); need 2 alpha >= delta")
    d.add_argument("--delta", type=float, default=None,
                   help="Newmark delta (default 0.5, no numerical damping; > 0.5 damps)")
    d.add_argument("--cx", dest="c_x", type=float, default=None,
                   help="initial displacement as a fraction of the way to the target (17)")
    d.add_argument("--cv", dest="c_v", type=float, default=None,
                   help="initial velocity as a multiple of the initial displacement (18)")
    d.add_argument("--remove-rigid", dest="remove_rigid", action="store_const", const=True,
                   default=None, help="remove rotation, translation and scale first (Horn): "
                                      "morph only the non-rigid part, in fewer steps")
    d.add_argument("--unmatched", choices=("arclength", "mean"), default=None,
                   help="contours: where unmatched nodes are pulled, between the partners "
                        "of their matched neighbours; arclength (default): spread evenly "
                        "along the target; mean: the paper's weighted mean (20), which "
                        "folds long unmatched runs")
    d.add_argument("--neighbours", type=int, default=None,
                   help="3D point sets: matched neighbours that pull an unmatched node")
    s = parser.add_argument_group("stopping")
    s.add_argument("--tol", type=float, default=None,
                   help="stop when matched nodes are this close to their partners on "
                        "average, as a fraction of the target's size (default 0.005)")
    s.add_argument("--tol-distance", dest="tol_distance", type=float, default=None,
                   help="the same tolerance in the input's units (overrides --tol)")
    s.add_argument("--max-steps", dest="max_steps", type=int, default=None,
                   help="maximum number of time steps (default 100)")
    s.add_argument("--equilibrium-tol", dest="equilibrium_tol", type=float, default=None,
                   help="stop when no node moves more than this fraction of the size")


def _add_inputs(parser):
    parser.add_argument("source", type=Path, help="source shape file (CSV, TSV, TXT, NPY, "
                        "NPZ, JSON, SVG, PNG/TIFF/JPEG mask or grey image, PLY/OBJ/STL/VTK)")
    parser.add_argument("target", type=Path, help="target shape file (same formats)")
    parser.add_argument("--nodes", type=int, default=None,
                        help="resample 2D contours to this many nodes (default: as in the "
                             "file; 200 for images and SVG)")
    parser.add_argument("--threshold", type=float, default=None,
                        help="grey images: level separating object from background")


# ------------------------------------------------------------------------------ commands


def _read_pair(source_path, target_path, options):
    from .io import read_shape

    kw = dict(nodes=options.get("nodes"), threshold=options.get("threshold"))
    source = read_shape(source_path, **kw)
    target = read_shape(target_path, **kw)
    if source.dim != target.dim:
        raise UsageError(f"{source_path} is {source.dim}D but {target_path} is "
                         f"{target.dim}D: both shapes must have the same dimension")
    return source, target


def _run_match(args) -> int:
    import numpy as np

    from .io import atomic_write
    from .matching import match

    options = {"nodes": args.nodes, "threshold": args.threshold}
    source, target = _read_pair(args.source, args.target, options)
    kw = {key: val for key, val in (("method", args.method), ("sigma", args.sigma),
                                    ("rotation", args.rotation)) if val is not None}
    result = match(source, target, **kw)
    table = np.column_stack([result.pairs, result.cost])
    header = "source,target,cost"
    fmt = ["%d", "%d", "%.6g"]
    if args.out is None:
        np.savetxt(sys.stdout, table, delimiter=",", header=header, comments="", fmt=fmt)
    else:
        with atomic_write(args.out) as tmp:
            np.savetxt(tmp, table, delimiter=",", header=header, comments="", fmt=fmt)
    if args.plot is not None:
        from .plot import plot_matches

        ax = plot_matches(source, target, result.pairs)
        with atomic_write(args.plot) as tmp:
            ax.figure.savefig(tmp, dpi=200, bbox_inches="tight")
    if not args.quiet:
        where = f" -> {args.out}" if args.out else ""
        print(f"{len(result.pairs)} pairs of {source.m} source and {target.m} target nodes "
              f"({result.method}){where}", file=sys.stderr)
    return 0


def _run_morph(args) -> int:
    run = morph_files(args.source, args.target, args.out, _options(args),
                      figures=args.figures, gif=args.gif, mp4=args.mp4, vtk=args.vtk,
                      html=args.html, quiet=args.quiet)
    if not args.quiet:
        _report(run.result, run.files)
    return 1 if args.strict and not run.result.converged else 0


def _run_track(args) -> int:
    run = track_files(args.inputs, args.out, _options(args), reference=args.reference,
                      correspondence=args.correspondence, cycle=args.cycle,
                      segments=args.segments, start_node=args.start_node,
                      figures=args.figures, gif=args.gif, quiet=args.quiet)
    result = run.result
    if not args.quiet:
        worst = float(result.distance.max())
        print(f"  {result.n_frames} frames of {result.points.shape[1]} nodes; largest "
              f"distance to a frame {worst:.3g}; strain {result.strain.min():+.3f} .. "
              f"{result.strain.max():+.3f}" + ("" if result.closure_error is None else
                                               f"; closure error {result.closure_error:.3g}"),
              file=sys.stderr)
        for path in run.files:
            print(f"  wrote {path}")
    return 0


def _run_app(args) -> int:
    from .app import serve

    serve(args.host, args.port, open_browser=args.open)
    return 0


def _run_batch(args) -> int:
    from . import batch

    items = batch.read_manifest(args.manifest)
    logging.getLogger("distributed").setLevel(logging.WARNING)  # not a line per worker event
    with _progress(len(items), quiet=args.quiet, what="batch", unit="item") as progress:
        done = batch.run(items, args.out, options=_options(args), figures=args.figures,
                         force=args.force, workers=args.workers, scheduler=args.scheduler,
                         engine=args.engine, progress=None if progress is None else
                         (lambda row, n, total: progress(n, None)))
    failed = [row for row in done.results if row.status != "ok" and row.status != "skipped"]
    if not args.quiet:
        counts = {s: sum(row.status == s for row in done.results)
                  for s in ("ok", "skipped", "failed", "interrupted")}
        print(f"  {len(items)} items: " + ", ".join(f"{n} {s}" for s, n in counts.items()
                                                    if n) + f" ({done.engine})",
              file=sys.stderr)
        for row in failed:
            print(f"  {row.id}: {row.status}: {row.error}", file=sys.stderr)
        for path in done.files:
            print(f"  wrote {path}")
    if done.interrupted:
        return 130
    return 1 if failed else 0


def morph_files(source, target, out, options: dict, *, figures: bool = True,
                gif: bool = True, mp4: bool = False, vtk: bool = False, html: bool = False,
                quiet: bool = True) -> ItemRun:
    """What ``modalmorph morph`` does: read two shape files, morph, write ``out``.

    ``out`` is filled all or nothing (:func:`modalmorph.io.atomic_output_dir`).

    Parameters
    ----------
    source, target : str or os.PathLike
        Shape files (any format of :func:`modalmorph.io.read_shape`).
    out : str or os.PathLike
        Output folder.
    options : dict
        Options as in a ``--config`` file (:func:`check_options`).
    figures, gif, mp4, vtk, html : bool, optional
        Which renderings to write beside the results (html: the self-contained report,
        :func:`modalmorph.report.write_html`).
    quiet : bool, optional
        No progress bar.

    Returns
    -------
    ItemRun
        The :class:`modalmorph.Morph` and the files written.
    """
    from .io import atomic_output_dir

    out = Path(out)
    with atomic_output_dir(out) as folder:  # checks out before any work
        shapes = _read_pair(source, target, options)
        result = _morph(*shapes, options, quiet=quiet)
        written = _write_outputs(result, folder, figures=figures, gif=gif, mp4=mp4, vtk=vtk)
        if html:
            from .report import input_images, write_html

            write_html(result, folder / "report.html",
                       title=f"{Path(source).name} → {Path(target).name}",
                       images=input_images(Path(source), Path(target)))
            written.append(Path("report.html"))
    return ItemRun(result=result, files=tuple(out / name for name in written))


def track_files(inputs, out, options: dict, *, reference: str = "previous",
                correspondence: str = "nearest", cycle: bool = False, segments: int = 6,
                start_node: int = 0, figures: bool = True, gif: bool = True,
                quiet: bool = True) -> ItemRun:
    """What ``modalmorph track`` does: read the frames, track, write ``out``.

    ``inputs`` is anything :func:`modalmorph.io.read_frames` reads; ``options`` as in a
    ``--config`` file; ``reference`` .. ``start_node`` as in :func:`modalmorph.track`.
    ``out`` is filled all or nothing. Returns the :class:`modalmorph.Track` and the files
    written.
    """
    from .io import atomic_output_dir, read_frames, save_track
    from .track import track

    frames = read_frames(inputs, threshold=options.get("threshold"),
                         nodes=options.get("nodes"))
    match_kw = _match_kwargs(options)
    with _progress(len(frames.shapes) - 1, quiet=quiet, what="tracking") as progress:
        result = track(frames.shapes, names=frames.names, reference=reference,
                       correspondence=correspondence, cycle=cycle,
                       segments=segments, start_node=start_node,
                       match_options=match_kw if correspondence == "modal" else None,
                       morph_options=_morph_kwargs(options),
                       progress=None if progress is None else
                       (lambda f, n: progress(f, None)))
    out = Path(out)
    with atomic_output_dir(out) as tmp:
        save_track(result, tmp)
        if figures or gif:
            from . import plot

            if figures:
                plot.save_track_figures(result, tmp)
            if gif:
                plot.animate_track(result, tmp / "track.gif")
        names = sorted(p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file())
    return ItemRun(result=result, files=tuple(out / name for name in names))


def _run_demo(args) -> int:
    from .datasets import load_hand, load_heart
    from .io import atomic_output_dir
    from .shape import Shape, resample

    cases = {
        "heart": (Shape(load_heart("diastole")), Shape(load_heart("systole")),
                  "left ventricle, end-diastole -> end-systole (Sunnybrook, CC0)"),
        "hands": (Shape(resample(load_hand(0), 120)), Shape(resample(load_hand(3), 140)),
                  "hand 0 (120 nodes) -> hand 3 (140 nodes) (statismo, BSD-3)"),
    }
    for name, (source, target, what) in cases.items():
        if not args.quiet:
            print(f"{name}: {what}", file=sys.stderr)
        with atomic_output_dir(args.out / name) as folder:
            result = _morph(source, target, {}, quiet=args.quiet)
            written = _write_outputs(result, folder, figures=True, gif=True, mp4=False,
                                     vtk=False)
        written = [args.out / name / path for path in written]
        if not args.quiet:
            _report(result, written)
    return 0


# ------------------------------------------------------------------------------ helpers


def _morph(source, target, options, *, quiet: bool):
    from .matching import match
    from .pipeline import morph

    kw = _morph_kwargs(options)
    matching = match(source, target, **_match_kwargs(options))
    with _progress(kw.get("max_steps", 100), quiet=quiet) as progress:
        return morph(source, target, matching=matching, progress=progress, **kw)


def _options(args) -> dict:
    """The merged options: the --config file, then the command line's."""
    options = load_config(args.config) if args.config else {}
    for key in (*_MORPH_OPTIONS, *_OTHER_OPTIONS):
        value = getattr(args, key, None)
        if value is not None:
            options[key] = value
    return options


def _match_kwargs(options) -> dict:
    """Keyword arguments of match() from the merged options."""
    names = {"method": "method", "rotation": "rotation", "match_sigma": "sigma"}
    return {arg: options[key] for key, arg in names.items() if key in options}


def _morph_kwargs(options) -> dict:
    """Keyword arguments of morph() from the merged options (config file, command line)."""
    import numpy as np

    kw = {key: options[key] for key in _MORPH_OPTIONS if key in options}
    if "modes" in kw:
        kw["modes"] = _parse_modes(kw["modes"])
    if "damping" in kw:
        damping = np.atleast_1d(np.asarray(kw["damping"], dtype=float))
        if damping.size not in (1, 2):
            raise UsageError(f"--damping takes one or two ratios, got {damping.size}")
        kw["damping"] = float(damping[0]) if damping.size == 1 else tuple(damping)
    kw.pop("rotation", None)  # a matching option: match() gets it
    kw["material"] = _material(options)
    return kw


def _material(options):
    from .material import MATERIALS, POLYETHYLENE, Material

    custom = [options.get(key) for key in ("E", "nu", "rho")]
    if any(value is not None for value in custom):
        if any(value is None for value in custom):
            raise UsageError("a custom material needs all of --E, --nu and --rho")
        return Material(*custom, name="custom")
    name = options.get("material")
    if name is None:
        return POLYETHYLENE
    if name not in MATERIALS:
        raise UsageError(f"unknown material {name!r}; choose one of {sorted(MATERIALS)}")
    return MATERIALS[name]


def _parse_modes(value):
    if isinstance(value, int | float) and not isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text == "all":
        return None
    try:
        if "/" in text:
            num, den = text.split("/")
            return float(num) / float(den)
        return float(text) if "." in text else int(text)
    except (ValueError, ZeroDivisionError):
        raise UsageError(f"--modes must be 'all', a count or a fraction, got {value!r}") \
            from None


def load_config(path: Path) -> dict:
    """Options from a TOML ``--config`` file, checked by :func:`check_options`."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as fh:
            config = tomllib.load(fh)
    except FileNotFoundError:
        raise UsageError(f"{path}: config file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from None
    return check_options(config, path)


def check_options(options: dict, where, *, extra: dict | None = None) -> dict:
    """Check the names and types of options as a ``--config`` file gives them.

    ``extra`` maps more known names to their types; ``where`` (a path, or a path and
    line) starts the messages. Returns a copy. Raises ``ValueError`` (``UsageError``)
    for an unknown name or a value of the wrong type.
    """
    known = {**_MORPH_OPTIONS, **_OTHER_OPTIONS, **(extra or {})}
    for key, value in options.items():
        if key not in known:
            raise UsageError(f"{where}: unknown option {key!r}; known: {', '.join(known)}")
        types = known[key]
        types = types if isinstance(types, tuple) else (types,)
        if float in types:
            types = (*types, int)
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            raise UsageError(f"{where}: option {key!r} has the wrong type "
                             f"({type(value).__name__})")
    return dict(options)


@contextlib.contextmanager
def _progress(total: int, *, quiet: bool, what: str = "morphing", unit: str = "step"):
    """A rich progress bar on a terminal; nothing when quiet or not on a terminal."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    try:
        from rich.progress import Progress
    except ImportError:
        yield None
        return
    with Progress(transient=True) as bar:
        task = bar.add_task(what, total=total)

        def update(step, distance):
            bar.update(task, completed=step, description=f"{what}: {unit} {step}" + (
                "" if distance is None else f", mean distance {distance:.3g}"))

        yield update


def _write_outputs(result, folder: Path, *, figures: bool, gif: bool, mp4: bool, vtk: bool):
    """Write every output into ``folder``; returns the files' paths relative to it."""
    from .io import save_result

    save_result(result, folder, params=result.params)
    if figures or gif or mp4:
        from . import plot

        if figures:
            plot.save_figures(result, folder)
        if gif:
            plot.animate(result, folder / "morph.gif")
        if mp4:
            plot.animate(result, folder / "morph.mp4")
    if vtk:
        from .plot import write_vtk_series

        write_vtk_series(result, folder / "vtk")
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def _report(result, written):
    print(f"  {len(result.matching.pairs)} matches; {result.stop_reason}", file=sys.stderr)
    for path in written:
        print(f"  wrote {path}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
