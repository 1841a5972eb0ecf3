"""The architecture of python/dualprobe (docs/design.md section 3) holds, and its checks bite.

- `lint-imports` (the contracts in pyproject.toml: layers, the reference is a check and
  independent, no import cycles) passes on the package;
- a product module that imports the reference breaks it (checked on a copy of the package);
- no module is over 500 lines;
- the compiled core is built (a missing extension fails here, it is never skipped);
- the checked-in `_core.pyi` is what pybind11-stubgen makes of the built extension.
"""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "python" / "dualprobe"
LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
MAX_LINES = 500


def lint_imports(cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache", "--no-logo"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )


def test_import_contracts_are_kept() -> None:
    result = lint_imports(REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "BROKEN" not in result.stdout and " KEPT" in result.stdout


def _copy_of_the_package(root: Path, name: str) -> None:
    """The package and its contracts under another top-level name (so the installed
    `dualprobe` cannot shadow the copy): every `dualprobe` becomes `name`."""
    target = root / "src" / name
    shutil.copytree(PACKAGE, target, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.pyi"))
    for path in target.rglob("*.py"):
        path.write_text(path.read_text(encoding="utf-8").replace("dualprobe", name), "utf-8")
    config = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    (root / "pyproject.toml").write_text(config.replace("dualprobe", name), "utf-8")


def test_a_product_module_importing_the_reference_breaks_the_contract(tmp_path: Path) -> None:
    name = "dpcopy"
    _copy_of_the_package(tmp_path, name)
    env = {"PYTHONPATH": str(tmp_path / "src"), "PATH": str(LINT_IMPORTS.parent)}
    clean = lint_imports(tmp_path, env)
    assert clean.returncode == 0, clean.stdout + clean.stderr  # the copy itself is fine
    leak = tmp_path / "src" / name / "models" / "leak.py"
    leak.write_text(f"from {name}.reference import difference  # noqa: F401\n", "utf-8")
    broken = lint_imports(tmp_path, env)
    assert broken.returncode != 0
    assert "The reference is a check" in broken.stdout and "BROKEN" in broken.stdout
    assert f"{name}.models.leak -> {name}.reference.difference" in broken.stdout


def test_no_module_is_over_500_lines() -> None:
    long = {
        str(path.relative_to(PACKAGE)): count
        for path in sorted(PACKAGE.rglob("*.py"))
        if (count := len(path.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert long == {}, f"modules over {MAX_LINES} lines: {long}"


def test_the_compiled_core_is_built() -> None:
    core = importlib.import_module("dualprobe._core")
    assert Path(core.__file__ or "").suffix in {".so", ".pyd"}
    for name in ("DifferenceEstimator", "SvfEstimator", "KalmanReconstructor", "estimate_svf"):
        assert hasattr(core, name), name


def test_checked_in_stub_matches_the_extension() -> None:
    result = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "stubs.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
