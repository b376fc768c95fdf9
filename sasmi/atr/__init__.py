"""Chips for ATR: torch datasets (datasets), COCO / YOLO labels (export), `sasmi atr-bench` (bench)."""
