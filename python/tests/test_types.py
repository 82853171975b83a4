"""The type stubs say what the compiled module has, and the package type-checks."""

import subprocess
import sys


def test_the_stubs_match_the_compiled_module():
    done = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "--ignore-disjoint-bases", "splatscene._native"],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_package_type_checks():
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--ignore-missing-imports", "-p", "splatscene"],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
