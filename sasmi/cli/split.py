"""`sasmi split ROOT --out DIR`: train / validation folders by scene group, linking to the real chips.

Assign whole scene groups of ROOT/MANIFEST.csv to train (~1 - fraction) and validation (~fraction),
balanced per category; write DIR/{train,validation}/CATEGORY/ as links to the real chips, each
side's own MANIFEST.csv (split DIR/train again to tune on train alone) and DIR/split.json.
Deterministic.
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("split", help="split a chip folder into train and validation by MANIFEST scene_group",
                       description=__doc__)
    p.add_argument("root", type=Path, help="chip folder with MANIFEST.csv (file, category, scene_group columns)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (train/ and validation/ "
                                                                          "must not exist yet)")
    p.add_argument("--fraction", type=float, default=0.25, help="validation share of each category")
    p.add_argument("--seed", type=int, default=0, help="changes which groups go to validation")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.chips.split import split_chips, write_split

    split = split_chips(args.root, args.fraction, args.seed)
    out = write_split(split, args.out)
    for side, counts in split.counts().items():
        chips = ", ".join(f"{n} {category}" for category, n in counts.items())
        print(f"{side}: {chips} from {len(split.groups[side])} scene groups")
    print(f"wrote {out / 'train'}, {out / 'validation'} and {out / 'split.json'}")
    return 0
