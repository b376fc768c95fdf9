"""`sasmi evaluate`: φ-FID ± , KID, precision/recall, nearest neighbours, t-SNE, target
preservation and pose sweeps of image sets against a real set, as report.md + metrics.json."""
from __future__ import annotations

import argparse
import functools
import re
import sys
from pathlib import Path

from sasmi.errors import SasmiError

NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "evaluate", help="compare image sets with real images; write report.md and metrics.json",
        description="Compare image sets with a real set in the φ space of a trained autoencoder and write "
                    "REPORT/report.md, REPORT/metrics.json and figures. Metric definitions: docs/evaluate.md.")
    p.add_argument("--real", required=True, type=Path, metavar="DIR", help="real images (the reference)")
    p.add_argument("--set", dest="sets", action="append", required=True, metavar="NAME=DIR",
                   help="an image set to evaluate, e.g. sasgan=runs/sasgan/translated; repeat for more sets")
    p.add_argument("--phi", type=Path, metavar="RUN",
                   help="autoencoder run (sasmi train autoencoder) or weights file (default: the shipped φ, "
                        "docs/models.md, so that figures compare across users)")
    p.add_argument("--out", required=True, type=Path, metavar="REPORT", help="folder for the report")
    p.add_argument("--preset", type=Path, metavar="TOML", help="pose sweeps: scene preset whose first target is swept")
    p.add_argument("--generator", type=Path, metavar="RUN", help="pose sweeps: SAS GAN run that translates them")
    p.add_argument("--bootstrap", type=int, default=500, metavar="N",  # EvalConfig's: the config stays unimported here
                   help="at most this many real splits and draws behind each figure and ± (default: 500; "
                        "fewer once a mean is known to 0.005; FID's ± from at most 100 resamples)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument("--no-two-sample", dest="two_sample", action="store_false",
                   help="skip the two-sample test (a classifier per set against the real chips, "
                        "15-70 s per set on 2 cores) (default: run it)")
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")
    cache = p.add_mutually_exclusive_group()
    cache.add_argument("--cache", type=Path, metavar="DIR",
                       help="where the real set's φ is kept between evaluations, keyed by its files and the φ "
                            "run (default: $XDG_CACHE_HOME/sasmi/phi, else ~/.cache/sasmi/phi)")
    cache.add_argument("--no-cache", action="store_true", help="compute the real set's φ afresh and keep nothing")
    p.set_defaults(run=run)


def parse_sets(specs: list[str], real: Path) -> dict[str, Path]:
    """["name=dir", ...] → {name: dir}; names must be unique, file-name safe and not 'real'."""
    sets: dict[str, Path] = {}
    for spec in specs:
        name, sep, folder = spec.partition("=")
        if not sep or not folder or not NAME.fullmatch(name):
            raise SasmiError(f"--set {spec!r}: expected NAME=DIR with NAME of letters, digits, '_', '.', '-'")
        if name in sets or name == "real":
            raise SasmiError(f"--set {spec!r}: the name {name!r} is {'reserved' if name == 'real' else 'used twice'}")
        if not Path(folder).is_dir():
            raise SasmiError(f"--set {spec!r}: {folder} is not a folder")
        sets[name] = Path(folder)
    if not real.is_dir():
        raise SasmiError(f"--real {real}: not a folder")
    return sets


def run(args: argparse.Namespace) -> int:
    from sasmi.eval import report as rep
    from sasmi.eval.cache import default_cache_dir
    from sasmi.eval.config import EvalConfig
    from sasmi.eval.features import as_encoder, describe_phi
    from sasmi.eval.evaluate import StderrLog
    from sasmi.images import FolderLock

    sets = parse_sets(args.sets, args.real)
    if (args.preset is None) != (args.generator is None):
        raise SasmiError("--preset and --generator: pose sweeps need both (or neither)")
    cfg = EvalConfig(bootstrap=args.bootstrap, seed=args.seed, **({} if args.two_sample else {"two_sample": None}))

    from sasmi.cli.common import resolve_device

    device = resolve_device(args.device)
    encoder = as_encoder(args.phi, device)
    log = StderrLog()
    inputs = {"real": str(args.real), **{f"set {k}": str(v) for k, v in sets.items()}, "phi": describe_phi(encoder),
              "preset": args.preset and str(args.preset), "generator": args.generator and str(args.generator),
              "seed": args.seed}
    report = rep.Report({"inputs": inputs}, (rep.Section(
        "Inputs", "\n".join(f"- {k}: `{v}`" for k, v in inputs.items() if v is not None)),))
    cache_dir = None if args.no_cache else args.cache or default_cache_dir()
    lock = FolderLock(args.out, "evaluating")  # two evaluations into one report would mix their figures
    try:
        path = _evaluate(args, report, sets, encoder, cfg, log, cache_dir, device)
    finally:
        lock.release()
    log(f"measured in φ: {describe_phi(encoder)}")
    log(f"wrote {path}")
    print(path)
    return 0


def _evaluate(args, report, sets, encoder, cfg, log, cache_dir, device) -> Path:
    from sasmi.chips.stats import median_statistics
    from sasmi.eval import report as rep
    from sasmi.eval import sweeps
    from sasmi.eval.config import SweepConfig
    from sasmi.eval.evaluate import evaluate_folders
    from sasmi.eval.stages import clear

    report += evaluate_folders(args.real, sets, encoder, args.out, cfg, log, cache_dir,
                               statistics=functools.partial(median_statistics, size=encoder.image_size),
                               resumable=True)  # a stopped evaluation's rerun goes on from its stage
    if args.preset is None:
        report += sweeps.skipped_pose_sweep("no --preset and --generator given")
    else:
        log("pose sweeps: render and translate")
        report += sweeps.pose_sweep_from_runs(args.preset, args.generator, args.out, SweepConfig(seed=args.seed),
                                              device)
    for warning in report.metrics["warnings"]:
        print(f"sasmi evaluate: warning: {warning}", file=sys.stderr)
    path = rep.write_report(args.out, report)
    clear(args.out)
    return path
