"""The output-folder rule (cosim.output_dir): refused before anything is written, cleared
only when asked, and names that cannot leave the outputs folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from cosim.errors import ConfigError
from cosim.output_dir import check_output_dir, prepare_output_dir, safe_name

WHAT = "run output folder"


def _listing(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def test_a_new_folder_is_created_with_its_parents(tmp_path):
    out = prepare_output_dir(tmp_path / "a" / "b", replace=False, what=WHAT)
    assert out.is_dir() and list(out.iterdir()) == []
    # an existing empty folder is fine too, and left empty
    assert prepare_output_dir(out, replace=False, what=WHAT) == out
    assert _listing(tmp_path) == ["a", "a/b"]  # no probe or temporary file left behind


def test_an_existing_file_is_refused_and_left_alone(tmp_path):
    f = tmp_path / "results.csv"
    f.write_text("keep me")
    with pytest.raises(ConfigError, match=r"run output folder .*results.csv is an existing file"):
        prepare_output_dir(f, replace=True, what=WHAT)
    assert f.read_text() == "keep me"


def test_a_path_under_a_file_is_refused(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    with pytest.raises(ConfigError, match=r"lies under .*file.txt, which is a file"):
        prepare_output_dir(f / "sub" / "run", replace=False, what=WHAT)
    assert _listing(tmp_path) == ["file.txt"]


@pytest.mark.parametrize("place", ["/sys/cosim_out", "/sys/cosim_out/deeper"])
def test_an_unwritable_place_is_refused_even_for_root(place):
    """/sys accepts no new entries for anyone (root included): the probe catches it."""
    with pytest.raises(ConfigError, match="cosim_out.*(not writable|cannot write)"):
        prepare_output_dir(place, replace=False, what=WHAT)
    assert not os.path.exists("/sys/cosim_out")


def test_a_read_only_folder_is_refused_for_a_normal_user(tmp_path):
    """chmod 500: refused through os.access for a normal user. Root may write anyway, so
    for root the check is that the rule and the file system agree."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.geteuid() != 0:
            with pytest.raises(ConfigError, match="not writable"):
                prepare_output_dir(ro / "run", replace=False, what=WHAT)
            assert not (ro / "run").exists()
        else:
            assert prepare_output_dir(ro / "run", replace=False, what=WHAT).is_dir()
    finally:
        ro.chmod(0o700)


def test_a_non_empty_folder_is_refused_unless_replace_then_only_it_is_cleared(tmp_path):
    out = tmp_path / "run"
    (out / "sub").mkdir(parents=True)
    (out / "trajectories.csv").write_text("old run")
    (out / "sub" / "x.txt").write_text("old")
    sibling = tmp_path / "other_run"
    sibling.mkdir()
    (sibling / "summary.csv").write_text("keep")
    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    (out / "link_to_outside").symlink_to(outside)
    (out / "link_to_sibling").symlink_to(sibling, target_is_directory=True)

    with pytest.raises(ConfigError, match=r"run output folder .*run already exists and is not "
                                          r"empty: pass --replace"):
        prepare_output_dir(out, replace=False, what=WHAT)
    assert (out / "trajectories.csv").read_text() == "old run"

    assert prepare_output_dir(out, replace=True, what=WHAT) == out
    assert list(out.iterdir()) == []
    # links were removed, not followed; the neighbours are untouched
    assert outside.read_text() == "keep"
    assert (sibling / "summary.csv").read_text() == "keep"


def test_keep_accepts_a_non_empty_folder_as_it_is(tmp_path):
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "results.csv").write_text("a")
    assert prepare_output_dir(out, replace=False, what=WHAT, keep=True) == out
    assert (out / "results.csv").read_text() == "a"


def test_replace_never_clears_the_current_folder_or_a_checkout(tmp_path, monkeypatch):
    work = tmp_path / "work"
    (work / "inner").mkdir(parents=True)
    (work / "precious.txt").write_text("x")
    monkeypatch.chdir(work / "inner")
    with pytest.raises(ConfigError, match="holds the current folder"):
        prepare_output_dir(work, replace=True, what=WHAT)
    with pytest.raises(ConfigError, match="holds the current folder"):
        prepare_output_dir(".", replace=True, what=WHAT)
    repo = tmp_path / "repo"
    (repo / ".git").mkdir(parents=True)
    with pytest.raises(ConfigError, match=r"source folder \(it holds .git\)"):
        prepare_output_dir(repo, replace=True, what=WHAT)
    assert (work / "precious.txt").exists() and (repo / ".git").is_dir()


def test_check_output_dir_writes_nothing(tmp_path):
    target = tmp_path / "new" / "deeper"
    assert check_output_dir(target, what=WHAT) == target
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("name, want", [
    ("../../x", "x"),
    ("..", "unnamed"),
    ("/etc/passwd", "etc_passwd"),
    ("ring fd/2", "ring_fd_2"),
    ("a\\..\\b", "a_._b"),
    (".hidden", "hidden"),
    ("", "unnamed"),
    ("open_road_capacity_smoke", "open_road_capacity_smoke"),
    ("x" * 300, "x" * 100),
])
def test_safe_name_is_one_folder_name(name, want):
    got = safe_name(name)
    assert got == want
    assert "/" not in got and "\\" not in got and ".." not in got and not got.startswith(".")


def test_a_safe_name_stays_inside_the_outputs_folder(tmp_path):
    root = tmp_path / "outputs"
    for hostile in ("../../x", "../..", "a/../../b", "/abs/path", "~/home", "x/./../../y"):
        target = (root / safe_name(hostile)).resolve()
        assert target.parent == root.resolve(), hostile
