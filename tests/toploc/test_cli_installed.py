"""The installed ``toploc`` console script, run from outside the source tree.

Tests import from the checkout; this one runs what ``pip install`` put on the PATH, so a
package missing from the distribution (as ``toploc.commands`` once was) fails here.
"""

import shutil
import subprocess

import pytest


@pytest.mark.parametrize("command", [["--help"], ["map", "--help"], ["eval", "--help"]])
def test_the_console_script_runs_every_group(tmp_path, command):
    script = shutil.which("toploc")
    assert script is not None, "the toploc console script is not installed (pip install .)"
    done = subprocess.run(
        [script, *command], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "Usage: toploc" in done.stdout
