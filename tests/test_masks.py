"""Mask PNGs: palette masks (as sasmi writes them) and plain gray ones read back as ids."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from sasmi.errors import SasmiError
from sasmi.masks import read_mask, write_class_mask, write_instance_mask


def test_palette_and_gray_masks_read_as_ids(tmp_path):
    ids = np.array([[0, 1, 2], [2, 1, 0]], np.uint8)
    write_class_mask(tmp_path / "class.png", ids)
    write_instance_mask(tmp_path / "inst.png", ids * 3)
    Image.fromarray(ids, mode="L").save(tmp_path / "gray.png")
    with Image.open(tmp_path / "class.png") as im:
        assert im.mode == "P"  # colours in a viewer
    assert np.array_equal(read_mask(tmp_path / "class.png"), ids)
    assert np.array_equal(read_mask(tmp_path / "inst.png"), ids * 3)
    assert np.array_equal(read_mask(tmp_path / "gray.png"), ids)


def test_a_colour_image_is_not_a_mask(tmp_path):
    Image.new("RGB", (4, 4)).save(tmp_path / "rgb.png")
    with pytest.raises(SasmiError, match="rgb.png"):
        read_mask(tmp_path / "rgb.png")
