"""`sasmi chips build`: chips cut from a made-up source tree as its MANIFEST says, checked, atomic, resumable."""
from __future__ import annotations

import numpy as np
from PIL import Image

from sasmi.cli.main import main

HEADER = "file,category,source_file,source_repo,crop_box,mirrored,scene_group,note\n"


def _tree(tmp_path):
    """A source tree of one 'repository' with two images whose pixels say where they are."""
    repo = tmp_path / "src" / "someone-sonar" / "data"
    repo.mkdir(parents=True)
    rows, cols = np.mgrid[0:90, 0:120]
    swath = ((rows * 7 + cols * 3) % 251).astype(np.uint8)  # every pixel's value tells its place
    Image.fromarray(swath).save(repo / "swath.png")
    Image.fromarray(np.full((40, 44, 3), 90, np.uint8)).save(repo / "patch.png")  # a colour file, one gray
    manifest = tmp_path / "MANIFEST.csv"
    manifest.write_text(HEADER
                        + 'targets/a.png,targets,someone-sonar/data/swath.png,someone/sonar@1,"10,20,42,52",0,g1,\n'
                        + 'targets/b.png,targets,someone-sonar/data/swath.png,someone/sonar@1,"50,5,82,37",1,g1,\n'
                        + 'seafloor/c.png,seafloor,someone-sonar/data/patch.png,someone/sonar@1,"2,3,26,27",0,g2,\n')
    return manifest, swath


def test_chips_are_cut_mirrored_and_resized_as_the_manifest_says(tmp_path, capsys):
    manifest, swath = _tree(tmp_path)
    out = tmp_path / "chips"
    argv = ["chips", "build", "--manifest", str(manifest), "--source", str(tmp_path / "src"), "--out", str(out),
            "--size", "32"]
    assert main(argv) == 0
    a, b, c = (np.asarray(Image.open(out / f)) for f in ("targets/a.png", "targets/b.png", "seafloor/c.png"))
    assert np.array_equal(a, swath[20:52, 10:42])
    assert np.array_equal(b, swath[5:37, 50:82][:, ::-1])  # mirrored: range grows to the right
    assert c.shape == (32, 32) and (c == 90).all()  # 24 px resized to 32, a flat gray stays flat
    assert (out / "MANIFEST.csv").read_text() == manifest.read_text()  # so that `sasmi split` can use the folder

    stamp = (out / "targets" / "a.png").stat().st_mtime_ns
    (out / "seafloor" / "c.png").unlink()
    assert main(argv) == 0  # a rerun writes only what is missing
    assert (out / "targets" / "a.png").stat().st_mtime_ns == stamp and (out / "seafloor" / "c.png").is_file()
    assert "(1 written now)" in capsys.readouterr().out

    assert main([*argv, "--check", str(out)]) == 0
    Image.fromarray(a ^ 1).save(tmp_path / "a.png")
    (tmp_path / "ref" / "targets").mkdir(parents=True)
    (tmp_path / "a.png").rename(tmp_path / "ref" / "targets" / "a.png")
    assert main([*argv, "--check", str(tmp_path / "ref")]) == 1  # one chip off by a gray level, two absent
    assert "0 of 3 chips equal" in capsys.readouterr().out


def test_a_missing_source_or_a_box_outside_its_image_writes_nothing(tmp_path, capsys):
    manifest, _ = _tree(tmp_path)
    out = tmp_path / "chips"
    base = ["chips", "build", "--source", str(tmp_path / "src"), "--out", str(out), "--size", "32"]
    bad = tmp_path / "missing.csv"
    bad.write_text(manifest.read_text() + 'targets/d.png,targets,someone-sonar/data/gone.png,x,"0,0,32,32",0,g3,\n')
    assert main([*base, "--manifest", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "line 5" in err[0] and "gone.png is missing" in err[0] and not out.exists()
    assert main([*base, "--manifest", str(bad), "--skip-missing"]) == 0  # the others are built
    assert "1 rows left out" in capsys.readouterr().out and (out / "targets" / "a.png").is_file()

    outside = tmp_path / "outside.csv"
    outside.write_text(HEADER + 'targets/e.png,targets,someone-sonar/data/swath.png,x,"100,70,132,102",0,g1,\n')
    assert main([*base[:-4], "--out", str(tmp_path / "other"), "--size", "32", "--manifest", str(outside)]) == 2
    assert "lies outside" in capsys.readouterr().err and not (tmp_path / "other").exists()
    escape = tmp_path / "escape.csv"
    escape.write_text(HEADER + '../e.png,targets,someone-sonar/data/swath.png,x,"0,0,32,32",0,g1,\n')
    assert main([*base[:-4], "--out", str(tmp_path / "other"), "--size", "32", "--manifest", str(escape)]) == 2
    assert "inside the output folder" in capsys.readouterr().err


def test_the_shipped_manifest_is_the_shared_chips_own():
    from conftest import SHARED_CHIPS
    from sasmi.chips.build import COLUMNS, manifest_path, read_manifest

    rows = read_manifest(manifest_path("sonar-chips"))
    assert len(rows) == 334 and all(c in rows[0] for c in (*COLUMNS, "category", "scene_group"))
    shared = SHARED_CHIPS / "MANIFEST.csv"
    if shared.is_file():  # beside the checkout: the two must not drift apart
        assert manifest_path("sonar-chips").read_text() == shared.read_text()
