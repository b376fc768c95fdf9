"""A render set -> the label formats ATR tools read: COCO JSON (pycocotools) or YOLO (ultralytics layout).

COCO: one `annotations.json` with images, annotations (bbox [x, y, w, h], segmentation
as RLE of the render's instance mask, area, iscrowd 0) and categories; the images stay
where they are (`file_name` is relative to the render set); each annotation's `role` says whether
it is the contact the chip is cut around ("target") or another object in view ("companion").
YOLO: `images/{train,val}/`, `labels/{train,val}/*.txt` (class cx cy w h, normalised)
and `data.yaml`; every tenth chip (index % 10 == 9) goes to val, so a set split the
same way every time.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import torch

from sasmi.atr.datasets import RenderSet
from sasmi.errors import SasmiError
from sasmi.images import FolderLock, atomic_path, check_room, write_text

FORMATS = ("coco", "yolo")


def _kept(target: dict, companions: bool) -> dict:
    """The chip's boxes, class ids, masks and companion flags; without companions if not `companions`."""
    keep = torch.ones_like(target["companion"]) if companions else ~target["companion"]
    return {key: target[key][keep] for key in ("boxes", "labels", "masks", "companion")}


def coco_dict(renders: RenderSet, companions: bool = True) -> dict:
    """The whole set as a COCO detection/instance-segmentation dict (without companions if not `companions`)."""
    from pycocotools import mask as mask_utils

    images, annotations = [], []
    for i in range(len(renders)):
        image, target = renders[i]
        _, h, w = image.shape
        image_id = int(target["image_id"])
        images.append({"id": image_id, "file_name": str(renders.image_path(i).relative_to(renders.folder)),
                       "width": w, "height": h})
        kept = _kept(target, companions)
        for box, category, mask, companion in zip(kept["boxes"].tolist(), kept["labels"].tolist(),
                                                  kept["masks"].numpy(), kept["companion"].tolist()):
            rle = mask_utils.encode(np.asfortranarray(mask))
            rle["counts"] = rle["counts"].decode("ascii")
            x0, y0, x1, y1 = box
            annotations.append({"id": len(annotations) + 1, "image_id": image_id, "category_id": int(category),
                                "bbox": [x0, y0, x1 - x0, y1 - y0], "segmentation": rle,
                                "area": float(mask_utils.area(rle)), "iscrowd": 0,
                                "role": "companion" if companion else "target"})
    categories = [{"id": i + 1, "name": name, "supercategory": "target"} for i, name in enumerate(renders.categories)]
    return {"info": {"description": f"sasmi render set {renders.folder.name}"}, "images": images,
            "annotations": annotations, "categories": categories}


def export_coco(folder: str | os.PathLike, out: str | os.PathLike, companions: bool = True) -> Path:
    renders = RenderSet(folder)
    out = Path(out)
    if out.is_dir():
        raise SasmiError(f"--out {out}: is a folder; give the JSON file to write")
    write_text(out, json.dumps(coco_dict(renders, companions)) + "\n")
    return out


def _yolo_lines(boxes: list, classes: list, w: int, h: int) -> str:
    lines = []
    for (x0, y0, x1, y1), c in zip(boxes, classes):
        lines.append(f"{c - 1} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} {(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}")
    return "\n".join(lines) + ("\n" if lines else "")


def export_yolo(folder: str | os.PathLike, out: str | os.PathLike, companions: bool = True) -> Path:
    """ultralytics layout: class ids 0-based (COCO's id - 1), one .txt per image, empty when no target shows;
    without companions if not `companions` (YOLO has no field to tell them apart)."""
    renders = RenderSet(folder)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SasmiError(f"--out {out}: exists and is not a folder")
    todo = [i for i in range(len(renders)) if not _yolo_image(renders, i, out).is_file()]  # a rerun keeps its copies
    check_room(out, sum(renders.image_path(i).stat().st_size for i in todo), f"{len(todo)} chips' images")
    lock = FolderLock(out, "exporting")  # two sets into one folder would mix their images and labels
    try:
        _write_yolo(renders, out, companions)
    finally:
        lock.release()
    return out


def _yolo_image(renders: RenderSet, i: int, out: Path) -> Path:
    """Where chip i's image goes: every tenth chip (index % 10 == 9) to val, the others to train."""
    split = "val" if renders.labels[i].index % 10 == 9 else "train"
    return out / "images" / split / renders.image_path(i).name


def _write_yolo(renders: RenderSet, out: Path, companions: bool) -> None:
    for i in range(len(renders)):
        image, target = renders[i]
        src, dst = renders.image_path(i), _yolo_image(renders, i, out)
        split = dst.parent.name
        if not dst.is_file():
            with atomic_path(dst) as tmp:
                shutil.copyfile(src, tmp)
        _, h, w = image.shape
        kept = _kept(target, companions)
        write_text(out / "labels" / split / f"{src.stem}.txt",
                   _yolo_lines(kept["boxes"].tolist(), kept["labels"].tolist(), w, h))
    names = "\n".join(f"  {i}: {name}" for i, name in enumerate(renders.categories))
    write_text(out / "data.yaml", f"# sasmi render set {renders.folder.resolve()}\npath: {out.resolve()}\n"
                                  f"train: images/train\nval: images/val\nnames:\n{names}\n")
