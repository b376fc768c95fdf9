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
