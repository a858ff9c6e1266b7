"""The ``modalmorph`` command line: ``demo``, ``match``, ``morph``, ``track``, ``strain``,
``batch``, ``stance`` and ``footprints`` (:mod:`modalmorph.apps.stance`) and ``app``.

The option flags are generated from the fields of the option classes
(:mod:`modalmorph.options`, :class:`modalmorph.options.AlignOptions`,
:class:`modalmorph.options.TrackOptions`): a flag per flat name, its help and default from
the field, grouped by the field's group; a ``--config`` TOML file takes the same flat
names, and the command line wins over it. What one run does is :mod:`modalmorph.apps.runs`.
"""

from __future__ import annotations

import argparse
import logging
import re
import signal
import sys
import time
import warnings
from pathlib import Path

from ..datasets import hand_shape, heart_shape
from ..errors import MorphDivergedError, OptionError
from ..figures import plot_matches
from ..io import atomic_output_dir, atomic_write
from ..matching import match
from ..matching.mirror import mirror_said
from ..options import MatchOptions, ReadOptions, StanceOptions, StrainOptions, flat_fields
from ..threads import tune_allocator
from ..version import __version__
from . import batch, strain
from . import stance as stance_app
from .app import serve
from .progress import batch_progress, interruptible, progress_bar
from .runs import (
    BATCH_CLASSES,
    PAIR_CLASSES,
    SEQUENCE_CLASSES,
    Settings,
    check_tools,
    compute_morph,
    default_text,
    morph_files,
    read_pair,
    track_files,
    write_morph,
)

__all__ = ["main", "build_parser", "add_option_flags", "flag_help", "flag_text",
           "load_config", "EXIT_CODES"]

log = logging.getLogger("modalmorph")

# Exit codes, documented in the help's epilog and the README.
EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NOT_CONVERGED, EXIT_LOST, EXIT_INTERRUPTED = \
    0, 1, 2, 3, 4, 130
EXIT_CODES = {
    EXIT_OK: "success",
    EXIT_FAILED: "batch: an item failed (the others are written)",
    EXIT_USAGE: "bad input or usage: one line names the file or option and the problem",
    EXIT_NOT_CONVERGED: "results written, but the tolerance was not reached (a warning "
                        "says where, even with -q)",
    EXIT_LOST: "batch: the Dask scheduler was lost (finished items are kept; run again "
               "to resume)",
    EXIT_INTERRUPTED: "interrupted by Ctrl-C: nothing half-written is left (a batch keeps its "
                      "finished items)",
}
_EPILOG = "exit codes:\n" + "\n".join(f"  {code:<4} {what}" for code, what in
                                       EXIT_CODES.items())
_MATCH_CLASSES = (ReadOptions, MatchOptions)
_INPUTS_HELP = ("shape file (CSV, TSV, TXT, NPY, NPZ, JSON, SVG, PNG/TIFF/JPEG mask or grey "
                "image, PLY/OBJ/STL/VTK)")


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (:data:`EXIT_CODES`)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help, --version (0) or a usage error (2)
        return int(exc.code or 0)
    tune_allocator()  # the process is ours: keep freed memory for reuse (modalmorph.threads)
    fresh = not logging.getLogger().handlers  # else a host (pytest) owns the logging
    if fresh:  # others' warnings, our information; log lines name flags, as errors do
        logging.basicConfig(level=logging.WARNING, format="%(message)s")
        log.setLevel(logging.WARNING if args.quiet else logging.INFO)
        logging.getLogger().handlers[0].addFilter(_FlagFilter())
    # a morph short of its tolerance is said once, by the status line or the warning below
    logging.getLogger("modalmorph.simulation").setLevel(logging.WARNING)
    # Library warnings are collected, not printed as they come: after a successful run each
    # is one line; after an error the error's line is the only one.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            with interruptible():
                code = args.run(args)
        except KeyboardInterrupt:  # output folders are replaced whole or not at all
            print("modalmorph: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except Exception as exc:  # noqa: BLE001 - one line, never a traceback
            known = isinstance(exc, ValueError | OSError | ImportError | MorphDivergedError)
            text = " ".join(str(exc).split())
            message = text if known and text else f"{type(exc).__name__}: {text}"
            print(f"modalmorph: error: {flag_text(message)}", file=sys.stderr)
            return EXIT_USAGE
    for warning in caught:
        _warn(str(warning.message))
    return code


def _warn(text: str) -> None:
    print(f"modalmorph: warning: {flag_text(' '.join(text.split()))}", file=sys.stderr)


def _flags() -> dict:
    """``{flat option name: (its flag, whether it is a --x/--no-x switch)}``."""
    return {name: (f.metadata.get("flag") or "--" + name.replace("_", "-"),
                   f.metadata["kind"] == "bool")
            for name, _cls, f in flat_fields((*SEQUENCE_CLASSES, StrainOptions,
                                              StanceOptions))}


_FLAGS = _flags()
# ``name=value`` of an option in a library message; the value ends at a space, a comma,
# a semicolon or a closing bracket
_KEYWORD = re.compile(r"(?<![\w.-])(" + "|".join(sorted(_FLAGS, key=len, reverse=True)) +
                      r")=([^\s,;)\]]*)")


def flag_text(text: str) -> str:
    """A library message as the command line says it: ``threshold=102`` becomes
    ``--threshold 102``, ``remove_rigid=True`` ``--remove-rigid`` (and ``False``
    ``--no-remove-rigid``): the flags of :func:`modalmorph.options.flat_fields`."""
    def flag(match: re.Match) -> str:
        (name, switch), value = _FLAGS[match[1]], match[2]
        end = "." if value.endswith(".") else ""  # the end of a sentence
        value = value.removesuffix(".").strip("'\"")
        if switch and value in ("True", "true", "False", "false"):
            return (name if value.lower() == "true" else "--no-" + name[2:]) + end
        return (f"{name} {value}" if value else name) + end

    return _KEYWORD.sub(flag, text)


class _FlagFilter(logging.Filter):
    """Log lines of the library with flags for keywords (:func:`flag_text`)."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = flag_text(record.getMessage()), None
        return True


# ------------------------------------------------------------------------------ parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (the option flags generated from the fields)."""
    parser = argparse.ArgumentParser(
        prog="modalmorph", epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Estimate, by physical principles, how one shape deforms into another "
                    "(Tavares & Pinho 2005): modal matching, Lagrange's dynamic equilibrium, "
                    "strain energy.")
    parser.add_argument("--version", action="version", version=f"modalmorph {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true",
                        help="print nothing but errors and warnings (no progress bar, no "
                             "file list)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, run, help, description):
        p = sub.add_parser(name, parents=[common], help=help, description=description,
                           epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
        p.set_defaults(run=run)
        return p

    _demo_parser(command("demo", _run_demo, "run the whole method on bundled real data "
                         "(heart, hands)", "Morph the bundled end-diastole heart contour "
                         "into end-systole, and one bundled hand into another, and write "
                         "results, figures and animations."))
    _match_parser(command("match", _run_match, "node correspondences only",
                          "Find correspondences between the nodes of two shapes by modal "
                          "matching."))
    _morph_parser(command("morph", _run_morph, "intermediate shapes, loads and strain energy",
                          "Match two shapes, integrate Lagrange's dynamic equilibrium to get "
                          "the intermediate shapes, and write results, figures and an "
                          "animation."))
    _track_parser(command("track", _run_track, "follow the nodes of the first frame through "
                          "a sequence", "Follow the nodes of the first frame through a "
                          "sequence by morphing frame 0 (or the tracked previous frame) onto "
                          "each frame; "
                          "write trajectories, strain energy and contour strain per frame, "
                          "figures and an animation."))
    strain.register(command, add_option_flags)
    _batch_parser(command("batch", _run_batch, "many pairs and sequences, on this machine "
                          "or a Dask cluster", "Run morph (source,target pairs) and track "
                          "(frames) for every item of a manifest, each into OUT/<id>/ "
                          "exactly as the single commands write it, and write "
                          "OUT/summary.csv. Items already complete in OUT are skipped; a "
                          "failing item is recorded and the batch goes on."))
    stance_app.add_parser(command, add_option_flags, _add_config, load_config)
    _app_parser(command("app", _run_app, "the interactive web application",
                        "Serve the method as a local web page: pick two shapes, set the "
                        "options, run, and explore the result."))
    return parser


def _demo_parser(p) -> None:
    p.add_argument("-o", "--out", type=Path, default=Path("modalmorph-demo"),
                   help="output folder (default: ./modalmorph-demo)")


def _match_parser(p) -> None:
    p.add_argument("source", type=Path, help="source " + _INPUTS_HELP)
    p.add_argument("target", type=Path, help="target shape file (same formats)")
    p.add_argument("-o", "--out", type=Path, default=None,
                   help="CSV file for the pairs (source,target,cost); default: stdout")
    p.add_argument("--plot", type=Path, default=None,
                   help="also draw the matches into this image (PNG, SVG, PDF)")
    add_option_flags(p, _MATCH_CLASSES)


def _morph_parser(p) -> None:
    p.add_argument("source", type=Path, help="source " + _INPUTS_HELP)
    p.add_argument("target", type=Path, help="target shape file (same formats)")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output folder (replaced as a whole)")
    _add_config(p)
    add_option_flags(p, PAIR_CLASSES)


def _track_parser(p) -> None:
    p.add_argument("inputs", nargs="+", type=Path, metavar="INPUTS",
                   help="the frames: several files, or one folder or glob pattern of images "
                        "or CSVs (natural order), a multi-page TIFF or animated GIF, an "
                        "(F, H, W) NPY stack of masks, an NPZ with an (F, n, d) array, or a "
                        "CSV with a frame column")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output folder (replaced as a whole)")
    _add_config(p)
    add_option_flags(p, SEQUENCE_CLASSES)


def _batch_parser(p) -> None:
    p.add_argument("manifest", type=Path, metavar="MANIFEST",
                   help="CSV (columns id, source, target or frames, or pressure with kind, "
                        "trial, template, subject, speed, and any option below with "
                        "underscores; cells are TOML values) or TOML ([[item]] tables with "
                        "the same keys); paths relative to it. Or a pressure file of many "
                        "trials (NPY/NPZ), or jiku (jiku-data's 600 trials): see --kind")
    p.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes on this machine (default: one per core)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler (tcp://host:port): run there; "
                        "inputs and OUT must be reachable by its workers")
    p.add_argument("--engine", choices=("auto", "dask", "processes"), default="auto",
                   help="auto (default): Dask with --scheduler, else whichever of a local "
                        "process pool and a Dask LocalCluster (modalmorph[dask]) ends first "
                        "by their measured start-up and per-item costs (the line 'engine:' "
                        "says which)")
    p.add_argument("--figures", choices=("none", "summary", "all"), default="none",
                   help="none (default): results only; summary: also one figure of the "
                        "whole batch (OUT/summary.png); all: every item's figures and "
                        "animation too, as morph and track write them")
    p.add_argument("--force", action="store_true", help="redo items already complete in OUT")
    p.add_argument("--keep-stale", action="store_true",
                   help="skip every item complete in OUT, even when its inputs' SHA-256 or "
                        "its options differ from those recorded in its result.json (by "
                        "default such an item is redone and the summary says why)")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="also print Dask's log lines (quiet without)")
    _add_config(p)
    add_option_flags(p, BATCH_CLASSES)
    batch.pressure.add_pressure_flags(p, {n for n, _c, _f in flat_fields(BATCH_CLASSES)})


def _app_parser(p) -> None:
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8765, help="port (default 8765; 0: any)")
    p.add_argument("--open", action="store_true", help="open the page in a browser")


def _add_config(p) -> None:
    p.add_argument("--config", type=Path, default=None,
                   help="TOML file of options, named as the flags with underscores (k = 50, "
                        "remove_rigid = true, damping = [0.5, 1.0], material = \"rubber\"); "
                        "the command line wins")


def add_option_flags(parser, classes) -> None:
    """A flag per field of the option classes (flat names), grouped by the field's group.

    Values stay text (``None`` when not given) and are parsed by
    :func:`modalmorph.options.split`; booleans are ``--x/--no-x``.
    """
    groups = {}
    for name, _cls, f in flat_fields(classes):
        meta = f.metadata
        group = groups.get(meta["group"]) or groups.setdefault(
            meta["group"], parser.add_argument_group(meta["group"]))
        kw = dict(dest=name, default=None, help=flag_help(f))
        if meta["kind"] == "bool":
            kw["action"] = argparse.BooleanOptionalAction
        elif meta["kind"] in ("damping", "material"):
            kw.update(nargs="+", metavar=meta["kind"].upper())
        elif meta["kind"] == "str" and meta.get("choices"):
            kw["choices"] = meta["choices"]
        else:
            kw["metavar"] = meta["kind"].upper()
        group.add_argument(meta.get("flag") or "--" + name.replace("_", "-"), **kw)


def flag_help(f) -> str:
    """A field's help with its default (``%`` escaped for argparse)."""
    text = f.metadata["help"]
    default = default_text(f)
    if default:
        text += f" (default: {default})"
    return text.replace("%", "%%")


# ------------------------------------------------------------------------------ options


def load_config(path: Path) -> dict:
    """Flat option values from a TOML ``--config`` file (checked when split)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise OptionError(f"{path}: config file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise OptionError(f"{path}: not valid TOML: {exc}") from None


def _flat_args(args, classes) -> dict:
    """The flat option values given: the --config file's, then the command line's."""
    values = {}
    config = getattr(args, "config", None)
    if config is not None:
        values = load_config(config)
        Settings.from_flat(values, classes, where=str(config))  # its own message first
    for name, _cls, _f in flat_fields(classes):
        value = getattr(args, name, None)
        if value is not None:
            values[name] = " ".join(value) if isinstance(value, list) else value
    return values


def _settings(args, classes) -> Settings:
    return Settings.from_flat(_flat_args(args, classes), classes)


# ------------------------------------------------------------------------------ commands


def _run_match(args) -> int:
    import numpy as np

    settings = _settings(args, _MATCH_CLASSES)
    source, target = read_pair(args.source, args.target, settings.read)
    result = match(source, target, **settings.match.record())
    table = np.column_stack([result.pairs, result.cost])
    kw = dict(delimiter=",", header="source,target,cost", comments="",
              fmt=["%d", "%d", "%.6g"])
    if args.out is None:
        np.savetxt(sys.stdout, table, **kw)
    else:
        with atomic_write(args.out) as tmp:
            np.savetxt(tmp, table, **kw)
    if args.plot is not None:
        ax = plot_matches(source, target, result.pairs)
        with atomic_write(args.plot) as tmp:
            ax.figure.savefig(tmp, dpi=200, bbox_inches="tight")
    if not args.quiet:
        where = f" -> {args.out}" if args.out else ""
        mirror = f"; {mirror_said(result.mirror)}" if result.mirror else ""
        print(f"{len(result.pairs)} pairs of {source.m} source and {target.m} target nodes "
              f"({result.method}){where}{mirror}", file=sys.stderr)
    return EXIT_OK


def _run_morph(args) -> int:
    settings = _settings(args, PAIR_CLASSES)
    start = time.perf_counter()
    with progress_bar(settings.morph.max_steps, quiet=args.quiet) as progress:
        run = morph_files(args.source, args.target, args.out, settings, progress=progress)
    _report(run.result, run.files, time.perf_counter() - start, quiet=args.quiet)
    return _converged_code([run.result], said=not args.quiet)


def _run_track(args) -> int:
    if stance_app.is_pressure_stack(args.inputs):  # every part, not one (issue 24)
        return stance_app.track_stack(args)
    settings = _settings(args, SEQUENCE_CLASSES)
    with progress_bar(None, quiet=args.quiet, what="tracking", unit="frame") as progress:
        run = track_files(args.inputs, args.out, settings, progress=None if progress is None
                          else (lambda frame, n_frames: progress(frame, None)))
    result = run.result
    if not args.quiet:
        frame = result.frames[0].frame
        unit = "input units" if frame is None else frame.unit
        closure = ("" if result.closure_error is None else
                   f"; closure error {result.closure_error:.3g} {unit}")
        slid = (f"; the nodes slid along the outline at {int(result.slid.sum())} frames (see "
                "the warning)" if result.slid.any() else "")
        print(f"{result.n_frames} frames of {result.points.shape[1]} nodes; largest distance "
              f"to a frame {float(result.distance.max()):.3g} {unit}; contour strain "
              f"{100 * result.strain.min():+.1f} % .. {100 * result.strain.max():+.1f} %"
              f"{closure}{slid}", file=sys.stderr)
        _list_files(run.files)
    return _converged_code(result.morphs)


def _run_app(args) -> int:
    stopped_by = serve(args.host, args.port, open_browser=args.open)
    return EXIT_INTERRUPTED if stopped_by == signal.SIGINT else EXIT_OK


def _run_batch(args) -> int:
    items = batch.pressure.batch_items(args.manifest, args.kind)
    settings = batch.pressure.batch_pressure(args, _settings(args, BATCH_CLASSES))
    engine = batch.Engine(args.engine, workers=args.workers, scheduler=args.scheduler)
    if engine.choice(len(items))[0]:
        _dask_logs(verbose=args.verbose)
    with batch_progress(quiet=args.quiet) as progress:
        done = batch.run(items, args.out, settings=settings, figures=args.figures,
                         force=args.force, keep_stale=args.keep_stale, engine=engine,
                         progress=progress)
    if not args.quiet:
        print(f"{len(items)} items: " + ", ".join(
            f"{done.counts[s]} {s}" for s in ("ok", "skipped", "failed", "interrupted")
            if done.counts.get(s)), file=sys.stderr)
        _list_files(done.files)
    short = _batch_errors(done)
    if done.lost:
        print(f"modalmorph: error: {done.lost}: {done.counts.get('interrupted', 0)} items "
              f"not finished, the others kept; run again to resume", file=sys.stderr)
        return EXIT_LOST
    if done.interrupted:
        print(f"modalmorph: interrupted: {done.counts.get('interrupted', 0)} items not "
              f"finished, the others kept; run again to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    if done.counts.get("failed"):
        return EXIT_FAILED
    if short:
        more = f" and {len(short) - _NAMED_ITEMS} more" if len(short) > _NAMED_ITEMS else ""
        _warn(f"{len(short)} items did not reach the tolerance: "
              f"{', '.join(short[:_NAMED_ITEMS])}{more}")
        return EXIT_NOT_CONVERGED
    return EXIT_OK


# Items named one by one in the messages of a batch (the summary lists them all).
_NAMED_ITEMS = 20


def _batch_errors(done) -> list[str]:
    """Print a line per failed item (the first ones); the ids of items short of their
    tolerance."""
    failed, short = 0, []
    for row in done.rows():
        if row.status == "failed":
            failed += 1
            if failed <= _NAMED_ITEMS:
                print(f"modalmorph: error: {row.id}: failed: {row.error}", file=sys.stderr)
        elif row.converged is False:
            short.append(row.id)
    if failed > _NAMED_ITEMS:
        print(f"modalmorph: error: {failed - _NAMED_ITEMS} more items failed (see "
              f"{done.out / 'summary.csv'})", file=sys.stderr)
    return short


def _dask_logs(*, verbose: bool) -> None:
    """Dask's log lines: shown with -v, else none (its loggers are set once imported)."""
    try:
        import distributed  # noqa: F401 - configures its loggers on import
    except ImportError:
        return
    level = logging.INFO if verbose else logging.CRITICAL + 1
    for name in [n for n in logging.root.manager.loggerDict
                 if n.split(".")[0] in ("distributed", "tornado", "bokeh")]:
        logging.getLogger(name).setLevel(level)
    logging.getLogger("distributed").setLevel(level)


def _run_demo(args) -> int:
    cases = {
        "heart": (heart_shape("diastole"), heart_shape("systole"),
                  "left ventricle, end-diastole -> end-systole (Sunnybrook, CC0)"),
        "hands": (hand_shape(0, 120), hand_shape(3, 140),
                  "hand 0 (120 nodes) -> hand 3 (140 nodes) (statismo, BSD-3)"),
    }
    settings = Settings()
    check_tools(settings.output)
    results = []
    for name, (source, target, what) in cases.items():
        if not args.quiet:
            print(f"{name}: {what}", file=sys.stderr)
        start = time.perf_counter()
        with atomic_output_dir(args.out / name) as folder:
            with progress_bar(settings.morph.max_steps, quiet=args.quiet) as progress:
                result = compute_morph(source, target, settings, progress=progress)
            written = write_morph(result, folder, settings)
        _report(result, [args.out / name / p for p in written], time.perf_counter() - start,
                quiet=args.quiet)
        results.append(result)
    return _converged_code(results, said=not args.quiet)


# ------------------------------------------------------------------------------ messages


def _converged_code(morphs, *, said: bool = False) -> int:
    """Exit code 3 with a warning (printed even with -q) when a morph fell short; its
    stop sentence only when the status line has not ``said`` it."""
    short = [m for m in morphs if not m.converged]
    for m in short:
        how = "" if said else f": {m.message}"
        _warn(f"the tolerance was not reached{how} (results written)")
    return EXIT_NOT_CONVERGED if short else EXIT_OK


def _report(result, written, seconds: float, *, quiet: bool) -> None:
    """One status sentence, then the files written (stdout)."""
    if quiet:
        return
    print(f"{result.source.m} -> {result.target.m} nodes, {len(result.matching.pairs)} "
          f"matches; {flag_text(result.message)}; {seconds:.1f} s", file=sys.stderr)
    _list_files(written)


def _list_files(paths) -> None:
    for path in paths:
        print(f"  wrote {path}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
