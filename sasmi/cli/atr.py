"""`sasmi export DIR --format coco|yolo --out PATH` and `sasmi atr-bench ...`: data for ATR models."""
from __future__ import annotations

import argparse
from pathlib import Path

from sasmi.cli.arguments import flag_or_all


def add_parser(sub: argparse._SubParsersAction) -> None:
    e = sub.add_parser("export", help="write a render set's labels as COCO JSON or YOLO (ultralytics) files",
                       description="COCO: one JSON (bbox, RLE instance masks, categories) that pycocotools loads; "
                                   "YOLO: images/, labels/ and data.yaml in the ultralytics layout "
                                   "(every tenth chip in val).")
    e.add_argument("folder", type=Path, help="render set (images/, masks/, instances/, labels.jsonl)")
    e.add_argument("--format", dest="label_format", choices=["coco", "yolo"], required=True)
    e.add_argument("--out", type=Path, required=True, help="COCO: the JSON file; YOLO: a folder")
    e.add_argument("--no-companions", dest="companions", action="store_false",
                   help="leave out the other objects in view (each target's role: companion), which are otherwise "
                        "labelled by their shape like the contact each chip is cut around (default: kept)")
    e.set_defaults(run=run_export)

    a = sub.add_parser("atr-bench", help="does synthetic data help a target/seafloor classifier on real chips?",
                       description="Trains a small fixed CNN on real, real+synthetic and synthetic(+real seafloor) "
                                   "chips over several seeds and scores it on real test chips (accuracy, ROC AUC).")
    a.add_argument("--real-train", type=Path, required=True, help="folder with targets/ and seafloor/")
    a.add_argument("--real-test", type=Path, required=True, help="folder with targets/ and seafloor/")
    a.add_argument("--synthetic", type=Path, required=True,
                   help="synthetic target chips (a render set, a translation, or a folder with targets/ [and seafloor/])")
    a.add_argument("--out", type=Path, required=True, help="folder for metrics.json, table.md, atr_bench.png")
    a.add_argument("--seeds", type=int, default=5, help="runs per training set, each with its own seed")
    a.add_argument("--size", type=int, default=128, help="chip size in px, a multiple of 16")
    a.add_argument("--steps", type=int, default=300, help="training batches per run")
    a.add_argument("--real-per-class", type=flag_or_all("--real-per-class"), nargs="+", default=[None], metavar="N|all",
                   help="real training chips drawn per class and seed (default: all); several values run several benches")
    a.set_defaults(run=run_atr_bench)


def run_export(args: argparse.Namespace) -> int:
    from sasmi.atr.export import export_coco, export_yolo

    out = (export_coco if args.label_format == "coco" else export_yolo)(args.folder, args.out, args.companions)
    print(f"wrote {out}")
    return 0


def run_atr_bench(args: argparse.Namespace) -> int:
    from sasmi.atr.bench import AtrConfig, atr_bench

    cfg = AtrConfig(size=args.size, seeds=args.seeds, steps=args.steps, real_per_class=tuple(args.real_per_class))
    metrics = atr_bench(args.real_train, args.real_test, args.synthetic, args.out, cfg)
    from sasmi.atr.bench import table_markdown

    print(table_markdown(metrics["results"]), end="")
    print(f"wrote {args.out}/metrics.json, table.md, atr_bench.png")
    return 0
