"""The ``modalmorph`` command line: ``demo``, ``match`` and ``morph``.

Exit codes: 0 success, 2 bad input or usage (a one-line message naming the file and the
problem), 1 a run that did not converge when ``--strict`` is given.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import warnings
from pathlib import Path

from . import __version__

__all__ = ["main"]

log = logging.getLogger("modalmorph")

# Options of morph() that the command line and a --config file may set.
_MORPH_OPTIONS = {
    "remove_rigid": bool, "k": float, "dt": float, "alpha": float, "delta": float,
    "damping": list, "c_x": float, "c_v": float, "sigma": float, "modes": (int, float, str),
    "scheme": str, "tol": float, "tol_distance": float, "max_steps": int,
    "equilibrium_tol": float, "unmatched": str, "neighbours": int,
}
_OTHER_OPTIONS = {"method": str, "nodes": int, "threshold": float, "material": str,
                  "E": float, "nu": float, "rho": float}


class UsageError(ValueError):
    """Bad input or usage: reported in one line with exit code 2."""


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
    match.add_argument("--sigma", type=float, default=None,
                       help="Gaussian width in units of the mean node spacing")
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
    morph.add_argument("--config", type=Path, default=None,
                       help="TOML file of options (same names as below, with underscores: "
                            "k = 50, remove_rigid = true, damping = [0.5, 1.0], ...); "
                            "options given on the command line win")
    morph.add_argument("--method", choices=("auto", "local", "global"), default=None,
                       help="matching method (see 'modalmorph match --help')")
    g = morph.add_argument_group("physics")
    g.add_argument("--material", default=None,
                   help="preset filling the objects: polyethylene (default, the paper's), "
                        "rubber or unit; or give --E, --nu, --rho")
    g.add_argument("--E", type=float, default=None, help="Young's modulus (custom material)")
    g.add_argument("--nu", type=float, default=None, help="Poisson's ratio (custom material)")
    g.add_argument("--rho", type=float, default=None, help="density (custom material)")
    g.add_argument("--sigma", type=float, default=None,
                   help="how far nodes interact: Gaussian width in units of the mean "
                        "spacing between nodes (default 1; larger is smoother but "
                        "ill-conditioned beyond ~2.5)")
    g.add_argument("--modes", default=None,
                   help="modes used: 'all' (default), a count (e.g. 40) or a fraction "
                        "(e.g. 2/3 or 0.66); fewer modes are cheaper and less exact")
    g.add_argument("--damping", type=float, nargs=2, metavar=("XI1", "XI2"), default=None,
                   help="damping ratios at the lowest and highest frequency (default 2 2, "
                        "twice critical: no overshoot; the paper used 0.005 0.03)")
    d = morph.add_argument_group("loads and time integration")
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
    s = morph.add_argument_group("stopping")
    s.add_argument("--tol", type=float, default=None,
                   help="stop when matched nodes are this close to their partners on "
                        "average, as a fraction of the target's size (default 0.005)")
    s.add_argument("--tol-distance", dest="tol_distance", type=float, default=None,
                   help="the same tolerance in the input's units (overrides --tol)")
    s.add_argument("--max-steps", dest="max_steps", type=int, default=None,
                   help="maximum number of time steps (default 100)")
    s.add_argument("--equilibrium-tol", dest="equilibrium_tol", type=float, default=None,
                   help="stop when no node moves more than this fraction of the size")
    o = morph.add_argument_group("outputs")
    o.add_argument("--no-figures", dest="figures", action="store_false",
                   help="skip the PNG/SVG figures")
    o.add_argument("--no-gif", dest="gif", action="store_false", help="skip the GIF")
    o.add_argument("--mp4", action="store_true", help="also write an MP4 (needs ffmpeg)")
    o.add_argument("--vtk", action="store_true",
                   help="also write a VTK time series (.vtu + .pvd) for ParaView")
    o.add_argument("--strict", action="store_true",
                   help="exit with code 1 when the morph does not reach the tolerance")
    morph.set_defaults(run=_run_morph)
    return parser


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


def _read_pair(args, options):
    from .io import read_shape

    kw = dict(nodes=options.get("nodes"), threshold=options.get("threshold"))
    source = read_shape(args.source, **kw)
    target = read_shape(args.target, **kw)
    if source.dim != target.dim:
        raise UsageError(f"{args.source} is {source.dim}D but {args.target} is "
                         f"{target.dim}D: both shapes must have the same dimension")
    return source, target


def _run_match(args) -> int:
    import numpy as np

    from .io import atomic_write
    from .matching import match

    options = {"nodes": args.nodes, "threshold": args.threshold}
    source, target = _read_pair(args, options)
    kw = {key: val for key, val in (("method", args.method), ("sigma", args.sigma))
          if val is not None}
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
    options = _load_config(args.config) if args.config else {}
    for key in (*_MORPH_OPTIONS, *_OTHER_OPTIONS):
        value = getattr(args, key, None)
        if value is not None:
            options[key] = value
    from .io import atomic_output_dir

    with atomic_output_dir(args.out) as folder:  # checks --out before any work
        source, target = _read_pair(args, options)
        result = _morph(source, target, options, quiet=args.quiet)
        written = _write_outputs(result, folder, figures=args.figures, gif=args.gif,
                                 mp4=args.mp4, vtk=args.vtk)
    written = [args.out / name for name in written]
    if not args.quiet:
        _report(result, written)
    return 1 if args.strict and not result.converged else 0


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

    kw = {key: options[key] for key in _MORPH_OPTIONS if key in options}
    if "modes" in kw:
        kw["modes"] = _parse_modes(kw["modes"])
    if "damping" in kw:
        kw["damping"] = tuple(kw["damping"])
    kw["material"] = _material(options)
    match_kw = {"method": options["method"]} if "method" in options else {}
    if "sigma" in options:
        match_kw["sigma"] = options["sigma"]
    matching = match(source, target, **match_kw)
    with _progress(kw.get("max_steps", 100), quiet=quiet) as progress:
        return morph(source, target, matching=matching, progress=progress, **kw)


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


def _load_config(path: Path) -> dict:
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
    known = {**_MORPH_OPTIONS, **_OTHER_OPTIONS}
    for key, value in config.items():
        if key not in known:
            raise UsageError(f"{path}: unknown option {key!r}; known: {', '.join(known)}")
        types = known[key]
        types = types if isinstance(types, tuple) else (types,)
        if float in types:
            types = (*types, int)
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            raise UsageError(f"{path}: option {key!r} has the wrong type "
                             f"({type(value).__name__})")
    return dict(config)


@contextlib.contextmanager
def _progress(total: int, *, quiet: bool):
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
        task = bar.add_task("morphing", total=total)

        def update(step, distance):
            bar.update(task, completed=step,
                       description=f"morphing: step {step}, mean distance {distance:.3g}")

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
    state = "converged" if result.converged else "did NOT converge"
    print(f"  {len(result.matching.pairs)} matches; {state} in {result.steps} steps "
          f"({result.stop_reason})", file=sys.stderr)
    for path in written:
        print(f"  wrote {path}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
