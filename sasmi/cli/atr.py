"""`sasmi export DIR --format coco|yolo --out PATH` and `sasmi atr-bench ...`: data for ATR models."""
from __future__ import annotations

import argparse
from pathlib import Path

from sasmi.cli.arguments import flag_or_all
from sasmi.cli.common import add_device

WAYS = ("real", "mixed", "alone", "pretrain", "replay")  # as sasmi.atr.bench.WAYS, which a test holds it to


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

    a = sub.add_parser("atr-bench", help="does synthetic data make a target/seafloor classifier better on real chips?",
                       description="Trains a classifier on real chips, and with synthetic chips used in several ways "
                                   "(mixed in, alone, pretrained then fine-tuned, with or without them replayed), "
                                   "over several seeds that share their real draws, and scores it on real test "
                                   "chips: accuracy, ROC AUC, Pd at a false-alarm rate, and paired differences "
                                   "with 95 % intervals. Resumes when rerun. See docs/atr.md.")
    a.add_argument("--real-train", type=Path, required=True, help="folder with targets/ and seafloor/")
    a.add_argument("--real-test", type=Path, required=True,
                   help="folder with targets/ and seafloor/, of scene groups never trained on")
    a.add_argument("--synthetic", type=Path, required=True,
                   help="synthetic target chips (a render set, a translation, or a folder with targets/ [and seafloor/])")
    a.add_argument("--synthetic-negatives", type=Path, metavar="DIR",
                   help="synthetic negatives (rendered seafloor, rocks, clutter: e.g. `sasmi render seafloor_only`), "
                        "used beside the real negatives (default: --synthetic's seafloor/, if any)")
    a.add_argument("--negatives", type=Path, metavar="DIR",
                   help="real training negatives instead of --real-train's seafloor/ (e.g. with hard negatives)")
    a.add_argument("--any-sonar", dest="same_sonar", action="store_false",
                   help="keep real negatives of every sonar (default: only the real targets' sonar, as the "
                        "MANIFEST.csv beside each folder names them)")
    a.add_argument("--out", type=Path, required=True, help="folder for metrics.json, table.md, atr_bench.png, runs.jsonl")
    a.add_argument("--ways", nargs="+", default=list(WAYS), choices=WAYS, metavar="WAY",
                   help=f"ways of using the synthetic chips: {', '.join(WAYS)}")
    a.add_argument("--net", default="small", help="the classifier: small (a fixed 4-layer CNN) or resnet18")
    a.add_argument("--seeds", type=int, default=10, help="real draws and trainings per arm")
    a.add_argument("--size", type=int, default=64, help="chip size in px, a multiple of 16")
    a.add_argument("--steps", type=int, default=200, help="training batches per network")
    a.add_argument("--real-per-class", type=flag_or_all("--real-per-class"), nargs="+", default=[0, 10, 40, None],
                   metavar="N|all", help="real training chips drawn per class and seed, each a bench; 0: no real "
                                         "target (default: 0 10 40 all)")
    add_device(a)
    a.set_defaults(run=run_atr_bench)


def run_export(args: argparse.Namespace) -> int:
    from sasmi.atr.export import export_coco, export_yolo

    out = (export_coco if args.label_format == "coco" else export_yolo)(args.folder, args.out, args.companions)
    print(f"wrote {out}")
    return 0


def run_atr_bench(args: argparse.Namespace) -> int:
    from sasmi.atr.bench import AtrConfig, atr_bench
    from sasmi.cli.common import resolve_device

    cfg = AtrConfig(size=args.size, seeds=args.seeds, steps=args.steps, net=args.net, ways=tuple(args.ways),
                    real_per_class=tuple(args.real_per_class), same_sonar=args.same_sonar)
    metrics = atr_bench(args.real_train, args.real_test, args.synthetic, args.out, cfg,
                        synthetic_negatives=args.synthetic_negatives, negatives=args.negatives,
                        device=resolve_device(args.device))
    from sasmi.atr.summary import table_markdown

    print(table_markdown(metrics["results"], metrics["paired"]), end="")
    print(f"wrote {args.out}/metrics.json, table.md, atr_bench.png")
    return 0
