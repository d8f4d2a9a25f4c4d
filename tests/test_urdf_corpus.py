"""The broken-URDF corpus (tests/corpus/urdf/): `mech import` reports exactly the diagnostics each
file's `<!-- expect: CODE line:col -->` lines name, located in the URDF (`file:line:col`, the
source line, a caret, a hint), exits 1 on an error without writing the output and 0 on warnings
only (writing a model that loads); never a traceback."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import mechdsl
import mechdsl.urdf
from mechdsl.cli import main

from conftest import TESTS

CORPUS = TESTS / "corpus" / "urdf"
EXPECT_LINE = re.compile(r"^<!-- expect: ([EW]\d{3}) (\d+):(\d+) -->\s*$")
HEADER = re.compile(r"^(?P<file>.*):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning)\[(?P<code>[EW]\d{3})\]: (?P<msg>.*)$")


def expectations() -> dict[str, list[tuple[str, int, int]]]:
    out = {}
    for path in sorted(CORPUS.glob("*.urdf")):
        lines = path.read_text(encoding="utf-8").splitlines()
        assert lines and EXPECT_LINE.match(lines[0]), f"{path.name} must start with <!-- expect: CODE line:col -->"
        out[path.name] = [(m[1], int(m[2]), int(m[3])) for m in map(EXPECT_LINE.match, lines) if m]
    return out


EXPECT = expectations()


def test_every_importer_code_has_a_file():
    codes = {c for exp in EXPECT.values() for c, _, _ in exp}
    src = "".join(p.read_text() for p in Path(mechdsl.urdf.__file__).parent.glob("*.py"))
    emitted = set(re.findall(r"[\"']([EW]0\d\d)[\"']", src))
    not_from_a_file = {"E001", "E003", "E005", "E006"}       # test_missing_and_unreadable_files
    assert emitted - not_from_a_file <= codes, f"importer codes with no corpus file: {sorted(emitted - codes)}"


@pytest.mark.parametrize("name", sorted(EXPECT))
def test_corpus_file(name, tmp_path, capsys):
    out = tmp_path / "robot.mech"
    rc = main(["import", str(CORPUS / name), "-o", str(out)])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.out + cap.err and "internal error" not in cap.err
    got, blocks = [], []
    for line in cap.err.splitlines():
        m = HEADER.match(line)
        if m:
            got.append((m["code"], int(m["line"]), int(m["col"])))
            blocks.append([line])
            assert m["file"] == str(CORPUS / name)
        elif blocks:
            blocks[-1].append(line)
    assert got == EXPECT[name], cap.err
    for b in blocks:                          # the URDF line, a caret, a hint
        assert len(b) >= 4 and b[2].strip().startswith("^") and b[-1].startswith("  help: "), "\n".join(b)
    if any(code.startswith("E") for code, _, _ in EXPECT[name]):
        assert rc == 1 and not out.exists()
    else:
        assert rc == 0 and out.exists()
        mechdsl.load(out)


def test_measured_inertia_accepts_the_triangle_example(tmp_path, capsys):
    out = tmp_path / "robot.mech"
    rc = main(["import", str(CORPUS / "E509_inertia_triangle.urdf"), "-o", str(out), "--measured-inertia"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    text = out.read_text()
    assert "measured_inertia = true" in text and "// measured inertia: I3 - (I1 + I2) = 0.1, 0.333 of I3" in text
    assert 'measured inertia: link "fore"' in cap.out
    m = mechdsl.load(out)
    assert m.model.body("fore").measured and not m.model.body("upper").measured


def test_floating_moves_a_robot_without_joints(tmp_path, capsys):
    out = tmp_path / "quad.mech"
    assert main(["import", str(CORPUS / "E027_nothing_moves.urdf"), "-o", str(out), "--floating"]) == 0
    m = mechdsl.load(out)
    assert m.model.coordinate_names == tuple(f"root_joint.{c}" for c in ("x", "y", "z", "q0", "q1", "q2", "q3"))
    assert "free-floating" in capsys.readouterr().out


def test_output_is_never_overwritten_without_force(tmp_path, capsys):
    out = tmp_path / "robot.mech"
    out.write_text("// mine\n")
    src = str(CORPUS / "W021_unreadable_mesh.urdf")
    assert main(["import", src, "-o", str(out)]) == 2
    assert out.read_text() == "// mine\n" and "--force" in capsys.readouterr().err
    assert main(["import", src, "-o", str(out), "--force"]) == 0
    assert out.read_text().startswith("// arm: imported from W021_unreadable_mesh.urdf")
    assert main(["import", src, "-o", str(tmp_path / "robot.txt")]) == 2


def test_missing_and_unreadable_files(tmp_path, capsys, monkeypatch):
    assert main(["import", str(tmp_path / "none.urdf")]) == 1
    assert "error[E001]" in capsys.readouterr().err
    assert main(["import", str(tmp_path)]) == 1
    assert "error[E003]" in capsys.readouterr().err
    (tmp_path / "empty.urdf").write_text("")
    assert main(["import", str(tmp_path / "empty.urdf")]) == 1
    assert "error[E020]" in capsys.readouterr().err
    import os

    os.mkfifo(tmp_path / "pipe.urdf")
    assert main(["import", str(tmp_path / "pipe.urdf")]) == 1       # refused before it is opened (no hang)
    assert "error[E006]" in capsys.readouterr().err
    from mechdsl.urdf import xmltree

    monkeypatch.setattr(xmltree, "MAX_BYTES", 100)
    assert main(["import", str(CORPUS / "E028_missing_mesh.urdf")]) == 1
    assert "error[E005]" in capsys.readouterr().err


def test_skip_missing_meshes_goes_on_without_drawing_them(tmp_path, capsys):
    """--skip-missing-meshes (skip_missing_meshes=True): the absent mesh is the warning W021 at the
    same <mesh>, the model is written and loads, and that link has no Shape (drawn by its inertia)."""
    src = CORPUS / "E028_missing_mesh.urdf"
    out = tmp_path / "robot.mech"
    assert main(["import", str(src), "-o", str(out), "--skip-missing-meshes"]) == 0
    err = capsys.readouterr().err
    assert f"{src}:7:23: warning[W021]: mesh 'package://arm_description/meshes/upper.stl' is not drawn" in err
    m = mechdsl.load(out)
    assert m.model.shapes == () and m.model.coordinate_names == ("shoulder.phi",)
    assert mechdsl.import_urdf(src, skip_missing_meshes=True) == out.read_text()
    with pytest.raises(mechdsl.MechError) as e:
        mechdsl.import_urdf(src)
    assert [d.code for d in e.value.diagnostics] == ["E028"]


def test_missing_meshes_are_counted_by_package_and_named_by_file(tmp_path, capsys):
    link = ('<link name="{n}"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.01"/></inertial>'
            '<visual><geometry><mesh filename="{f}"/></geometry></visual></link>')
    joint = '<joint name="j{n}" type="revolute"><parent link="{p}"/><child link="{n}"/><axis xyz="0 0 1"/></joint>'
    files = ["package://gone/a.stl", "package://gone/b.stl", "meshes/c.stl", "package://gone/d.stl"]
    parts = ['<robot name="r">', '<link name="base"/>']
    for k, f in enumerate(files):
        parts += [link.format(n=f"l{k}", f=f), joint.format(n=f"l{k}", p="base" if k == 0 else f"l{k - 1}")]
    src = tmp_path / "r.urdf"
    src.write_text("\n".join(parts + ["</robot>"]))
    assert main(["import", str(src)]) == 1
    err = capsys.readouterr().err
    heads = [line for line in err.splitlines() if "error[E028]" in line]
    assert len(heads) == 2, err
    assert heads[0].startswith(f"{src}:3:") and "'package://gone/a.stl' and 2 more of its package: package 'gone'" in heads[0]
    assert heads[1].startswith(f"{src}:7:") and f"'meshes/c.stl': no file {tmp_path / 'meshes' / 'c.stl'}" in heads[1]
    assert "check the path" in err
