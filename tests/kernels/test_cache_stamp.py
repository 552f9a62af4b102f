"""Stale numba caches of the kernels are dropped when any kernel source changes."""

from pathlib import Path

from reachconf_kernels import cache_stamp


def _fake_package(tmp_path: Path) -> Path:
    pkg = tmp_path / "kern"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text("def f():\n    return 1\n")
    (pkg / "caller.py").write_text("def g():\n    return 2\n")
    return pkg


def _cache_files(pkg: Path):
    cache = pkg / "__pycache__"
    cache.mkdir(exist_ok=True)
    files = [cache / "caller.g-1.py311.nbi", cache / "caller.g-1.py311.1.nbc", cache / "callee.f-1.py311.nbi"]
    for f in files:
        f.write_bytes(b"x")
    other = cache / "caller.cpython-311.pyc"  # Python's own bytecode is not numba's to drop
    other.write_bytes(b"y")
    return files, other


def test_caches_survive_while_the_sources_are_unchanged_and_go_when_a_callee_changes(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _fake_package(tmp_path)
    assert cache_stamp.drop_stale_caches(pkg) == 0  # first import: nothing cached yet, stamp written
    assert (pkg / "__pycache__" / cache_stamp.STAMP_NAME).is_file()
    files, other = _cache_files(pkg)
    assert cache_stamp.drop_stale_caches(pkg) == 0
    assert all(f.exists() for f in files)
    # only the callee changes: the caller's entry (with the old callee inlined) must go too
    (pkg / "callee.py").write_text("def f():\n    return 3\n")
    assert cache_stamp.drop_stale_caches(pkg) == len(files)
    assert not any(f.exists() for f in files)
    assert other.exists()
    # stamped again: the next import keeps what is compiled afresh
    files, _ = _cache_files(pkg)
    assert cache_stamp.drop_stale_caches(pkg) == 0
    assert all(f.exists() for f in files)


def test_a_new_kernel_module_changes_the_digest(tmp_path):
    pkg = _fake_package(tmp_path)
    before = cache_stamp.sources_digest(pkg)
    (pkg / "extra.py").write_text("")
    assert cache_stamp.sources_digest(pkg) != before


def test_the_installed_package_is_stamped_with_its_current_sources():
    import reachconf_kernels

    folder = Path(reachconf_kernels.__file__).parent
    stamp = cache_stamp.cache_folder(folder / "__init__.py") / cache_stamp.STAMP_NAME
    assert stamp.read_text().strip() == cache_stamp.sources_digest(folder)
