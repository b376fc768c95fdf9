"""`sasmi sheet`: the sheet is written beside the folder (never into the chips), bad flags exit 2."""
import numpy as np
import pytest
from PIL import Image

from sasmi.cli import main as cli
from sasmi.images import list_images, write_gray
from sasmi.masks import write_class_mask


@pytest.fixture
def renders(tmp_path):
    folder = tmp_path / "renders"
    rng = np.random.default_rng(0)
    for i in range(5):
        mask = np.zeros((16, 16), np.uint8)
        mask[4:8, 4:8], mask[4:8, 8:14] = 1, 2
        write_gray(folder / "images" / f"{i:06d}.png", rng.uniform(0, 1, (16, 16)))
        write_class_mask(folder / "masks" / f"{i:06d}.png", mask)
    return folder


def test_default_sheet_goes_beside_the_folder(renders, capsys):
    before = list_images(renders)
    assert cli.main(["sheet", str(renders), "--columns", "2"]) == 0
    sheet = renders.parent / "renders_sheet.png"
    assert capsys.readouterr().out.strip() == f"wrote {sheet}"
    assert list_images(renders) == before and not list(renders.rglob("*sheet*"))
    with Image.open(sheet) as image:  # 3 rows of 2 tiles, each tile the chip and its outlined copy
        assert image.size == (2 * (32 + 4) + 4, 3 * (16 + 4) + 4)


@pytest.mark.parametrize("flag", ["--columns", "--limit"])
def test_zero_is_a_one_line_error(renders, capsys, flag):
    assert cli.main(["sheet", str(renders), flag, "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sasmi sheet: error: ") and err.count("\n") == 1 and flag in err and "allowed: 1" in err
    assert not (renders.parent / "renders_sheet.png").exists()


def test_several_folders_show_each_chip_side_by_side(renders, tmp_path):
    translated = tmp_path / "translated"
    for i in range(5):
        write_gray(translated / "images" / f"{i:06d}.png", np.full((16, 16), 0.5))
        write_class_mask(translated / "masks" / f"{i:06d}.png", np.zeros((16, 16), np.uint8))
    out = tmp_path / "sheet.png"
    assert cli.main(["sheet", str(renders), str(translated), "--out", str(out), "--columns", "5"]) == 0
    with Image.open(out) as image:  # 1 row of 5 tiles: render | translation | translation outlined
        assert image.size == (5 * (48 + 4) + 4, 16 + 8)
        sheet = np.asarray(image)
    first = sheet[4:20, 4:52, 0]
    np.testing.assert_array_equal(first[:, :16], np.asarray(Image.open(renders / "images" / "000000.png")))
    assert (first[:, 16:32] == 128).all()


def test_several_folders_must_hold_the_same_chips(renders, tmp_path, capsys):
    other = tmp_path / "other"
    write_gray(other / "000000.png", np.zeros((16, 16)))
    assert cli.main(["sheet", str(other), str(renders), "--out", str(tmp_path / "s.png")]) == 2
    assert "has no chip 000001.png" in capsys.readouterr().err
    assert not (tmp_path / "s.png").exists()
