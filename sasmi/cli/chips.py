"""`sasmi chips build --manifest MANIFEST.csv --source DIR --out DIR`: real chips cut from their public sources."""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("chips", help="real chips: build them from their public sources, as a MANIFEST describes")
    kinds = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    b = kinds.add_parser("build", help="cut every chip of a MANIFEST.csv from a local copy of its sources",
                         description="Cut each row's crop_box from SOURCE/source_file (8-bit luminance), mirror it "
                                     "where mirrored is 1, resize it to --size where the box is not that square, "
                                     "and write OUT/file and OUT/MANIFEST.csv. Every row is checked first; a rerun "
                                     "writes only the chips not yet there. See README, Real chips.")
    b.add_argument("--manifest", default="sonar-chips", metavar="CSV|NAME",
                   help="file, source_file, crop_box, mirrored columns (and category, scene_group for sasmi split); "
                        "sonar-chips: the shipped MANIFEST of the public chips README names")
    b.add_argument("--source", type=Path, required=True, metavar="DIR",
                   help="clones of the public repositories, each as DIR/OWNER-NAME at the MANIFEST's commit")
    b.add_argument("--out", type=Path, required=True, metavar="DIR", help="the chip folder to write")
    b.add_argument("--size", type=int, default=128, help="chip size in px")
    b.add_argument("--skip-missing", action="store_true",
                   help="leave out rows whose source file is absent, with one line saying how many "
                        "(default: refuse, naming the first)")
    b.add_argument("--check", type=Path, metavar="DIR",
                   help="compare every built chip with DIR's, pixel for pixel; exit 1 if any differs")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.chips.build import build_chips, compare

    done = build_chips(args.manifest, args.source, args.out, args.size, args.skip_missing)
    built = done["built"]
    print(f"sasmi chips build: {len(built)} of {done['rows']} chips in {args.out} ({done['written']} written now)")
    if args.check is None:
        return 0
    differ = compare(args.out, args.check, built)
    print(f"sasmi chips build: {len(built) - len(differ)} of {len(built)} chips equal {args.check}'s pixel for pixel"
          + (f"; differ: {', '.join(differ[:5])}{' ...' if len(differ) > 5 else ''}" if differ else ""))
    return 1 if differ else 0
