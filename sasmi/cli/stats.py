"""`sasmi stats DIR [DIR ...]`: image statistics of chip folders side by side, without masks."""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stats", help="compare image statistics (shadow/highlight size, gray levels, speckle) of "
                                     "chip folders",
                       description="Per folder, the median [quartiles] over chips of shadow and highlight size, "
                                   "gray levels, saturation, speckle looks, floor autocorrelation, range fall-off "
                                   "and shadow level, found in the images (no masks needed), with each folder's "
                                   "ratio to the first. Render sets also report the error against their masks. "
                                   "Definitions: docs/matching.md.")
    p.add_argument("folders", type=Path, nargs="+", metavar="DIR",
                   help="chip folders (or render sets); the first is the reference, e.g. the real chips")
    p.add_argument("--size", type=int, default=128, help="chips are resized/cropped to this size")
    p.add_argument("--json", type=Path, metavar="FILE", help="write per-chip values and summaries here")
    p.add_argument("--plot", type=Path, metavar="FILE", help="write histograms and ratio bars here (PNG)")
    p.add_argument("--check", action="store_true",
                   help="mark each statistic ok/FAIL against the first folder with the tolerances of docs/matching.md; "
                        "exit 1 when any fails")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.errors import SasmiError
    from sasmi.preprocess import check_size
    from sasmi.chips.stats import chip_statistics
    from sasmi.chips.compare import check, plot, table, write_json

    check_size(args.size)
    for folder in args.folders:
        if not folder.is_dir():
            raise SasmiError(f"{folder}: not a folder")
    results = [chip_statistics(folder, args.size) for folder in args.folders]
    print(table(results, with_check=args.check))
    if args.json:
        write_json(results, args.json)
        print(f"wrote {args.json}")
    if args.plot:
        plot(results, args.plot)
        print(f"wrote {args.plot}")
    if args.check and len(results) > 1:
        return 0 if all(all(check(results[0], r).values()) for r in results[1:]) else 1
    return 0
