"""The CPU backend refuses a libLLVM known to abort the process on this CPU, in one line with the
fix, before any kernel is compiled; the README's commands install what it needs."""
from __future__ import annotations

from pathlib import Path

import pytest

from rangesim.core import backend

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def fresh_checks(monkeypatch):
    backend.llvm_problem.cache_clear()
    yield
    backend.llvm_problem.cache_clear()


@pytest.mark.parametrize(("flags", "version", "refused"), [
    ({"avx2", "avx512f"}, (15, 0, 6), True),   # Debian 12's default: "Cannot select: fmaximum"
    ({"avx2", "avx512f"}, (16, 0, 6), True),
    ({"avx2", "avx512f"}, (19, 1, 7), False),
    ({"avx2"}, (15, 0, 6), False),             # AVX2 code: not the failing 16-lane selection
    (None, (15, 0, 6), False),                 # flags unknown: no guess
])
def test_llvm_refused_only_where_it_aborts(monkeypatch, fresh_checks, flags, version, refused):
    import drjit as dr

    monkeypatch.setattr(backend, "cpu_flags", lambda: None if flags is None else frozenset(flags))
    monkeypatch.setattr(dr.detail, "llvm_version", lambda: version)
    problem = backend.llvm_problem()
    assert (problem is not None) == refused
    if refused:
        assert "libllvm19" in problem and f"{version[0]}.{version[1]}.{version[2]}" in problem
        assert "\n" not in problem


def test_cpu_flags_reads_proc_cpuinfo():
    flags = backend.cpu_flags()
    if not Path("/proc/cpuinfo").is_file():
        assert flags is None
    else:
        assert flags and all(" " not in f and ":" not in f for f in flags)


def test_readme_commands_install_the_system_libraries():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    blocks = [b.split("```")[0].strip() for b in readme.split("```bash\n")[1:3]]
    assert all(b.startswith("sh system-deps.sh && pip install -e ") for b in blocks), blocks
    assert blocks[1] in ci.splitlines()  # CI runs the README's test command itself
