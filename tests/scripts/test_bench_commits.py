"""scripts/bench_commits.py: a job run with another tree's code imports that tree's package and
reads that tree's shaders, in the pool's spawned workers too (an editable install's finder maps
``xrayraster.shaders`` to this checkout whatever PYTHONPATH says). The script's code runs in a
child process (tests import no benchmark code)."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

WHERE = """
import multiprocessing

def where(_):
    import importlib.util
    import xrayraster
    return xrayraster.__file__, importlib.util.find_spec("xrayraster.shaders") is None

if __name__ == "__main__":
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        print([where(0), pool.map(where, [0])[0]])
"""


def test_a_job_in_another_tree_reads_that_trees_package_and_shaders(tmp_path):
    tree = tmp_path / "tree"
    (tree / "xrayraster").mkdir(parents=True)
    (tree / "xrayraster" / "__init__.py").write_text("")  # no shaders subpackage: the real one falls back to tree/shaders
    (tree / "where.py").write_text(WHERE)
    env = subprocess.run(
        [sys.executable, "-c", "import json, sys; from pathlib import Path; from scripts.bench_commits import tree_env; "
         "print(json.dumps(tree_env(Path(sys.argv[1]), Path(sys.argv[2]))))", str(tree), str(tmp_path / "boot")],
        cwd=ROOT, capture_output=True, text=True, check=True).stdout
    done = subprocess.run([sys.executable, "where.py"], cwd=tree, env=json.loads(env), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    here = str(tree / "xrayraster" / "__init__.py")
    assert done.stdout.strip() == repr([(here, True), (here, True)])
