"""With ``--json`` stdout holds exactly one JSON object: what a command prints while it works
(progress lines, notices, output of the worker processes it starts, which write to the file
descriptor) goes to stderr."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""
    import os, sys
    from studies.cli import parser as cli
    from studies.cli import info as info_command

    info = info_command.info

    def noisy(args):
        print("a progress line")                         # this process
        os.write(1, b"a worker's line on descriptor 1\\n")  # a child process writes to the descriptor
        return info(args)

    info_command.info = noisy
    sys.exit(cli.main(["info", "--mesh", "2x2x2", *sys.argv[1:]]))
""")


def test_progress_goes_to_stderr_and_stdout_holds_the_object():
    p = subprocess.run([sys.executable, "-c", SCRIPT, "--json"], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert len(lines) == 1, p.stdout
    assert json.loads(lines[0])["status"] == "ok"
    assert "a progress line" in p.stderr and "a worker's line on descriptor 1" in p.stderr


def test_without_json_stdout_holds_the_table_only():
    p = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "progress" not in p.stdout and "vertices" in p.stdout
