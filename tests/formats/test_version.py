"""formats.version: the package version and the git commit, read from the checkout's files without git."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from formats import version
from formats.version import describe, git_commit, package_version, provenance

SHA_A = "a" * 40
SHA_B = "b" * 40


def _repo(root: Path) -> Path:
    git = root / ".git"
    (git / "refs" / "heads").mkdir(parents=True)
    return git


def test_package_version_is_the_installed_distributions() -> None:
    from importlib import metadata

    assert package_version() == metadata.version("vtdslam")


def test_package_version_without_the_distribution(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(version, "DISTRIBUTION", "no-such-distribution-here")
    assert package_version() == version.UNKNOWN_VERSION


def test_commit_from_a_loose_ref_a_packed_ref_and_a_detached_head(tmp_path: Path) -> None:
    git = _repo(tmp_path)
    (git / "HEAD").write_text("ref: refs/heads/main\n")
    (git / "refs" / "heads" / "main").write_text(SHA_A + "\n")
    assert git_commit(tmp_path) == SHA_A
    (git / "refs" / "heads" / "main").unlink()
    (git / "packed-refs").write_text(f"# pack-refs with: peeled fully-peeled sorted\n{SHA_B} refs/heads/main\n")
    assert git_commit(tmp_path) == SHA_B
    (git / "HEAD").write_text(SHA_A + "\n")
    assert git_commit(tmp_path) == SHA_A


def test_commit_of_a_worktree_reads_its_own_head_and_the_common_refs(tmp_path: Path) -> None:
    git = _repo(tmp_path / "main")
    (git / "refs" / "heads" / "wt").write_text(SHA_B + "\n")
    own = git / "worktrees" / "wt"
    own.mkdir(parents=True)
    (own / "HEAD").write_text("ref: refs/heads/wt\n")
    (own / "commondir").write_text("../..\n")
    tree = tmp_path / "wt"
    tree.mkdir()
    (tree / ".git").write_text(f"gitdir: {own}\n")
    assert git_commit(tree) == SHA_B


@pytest.mark.parametrize("setup", ["nothing", "unborn", "garbage", "empty_git_file"])
def test_no_commit_is_none_never_an_error(tmp_path: Path, setup: str) -> None:
    if setup != "nothing" and setup != "empty_git_file":
        git = _repo(tmp_path)
        (git / "HEAD").write_text("ref: refs/heads/main\n" if setup == "unborn" else "not a sha\n")
    elif setup == "empty_git_file":
        (tmp_path / ".git").write_text("")
    assert git_commit(tmp_path) is None


def test_this_checkout_matches_git_when_git_is_there() -> None:
    try:
        done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=version.CHECKOUT, capture_output=True, text=True,
                              timeout=30)
    except OSError:
        pytest.skip("no git program")
    if done.returncode != 0:
        pytest.skip("not a git checkout")
    assert git_commit() == done.stdout.strip()


def test_describe() -> None:
    assert describe({"version": "1.2.3", "commit": SHA_A}) == "1.2.3 (commit aaaaaaaaaaaa)"
    assert describe({"version": "1.2.3", "commit": None}) == "1.2.3"
    assert set(provenance()) == {"version", "commit"}

