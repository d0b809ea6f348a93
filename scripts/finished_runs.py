"""Runs a script has finished, recognised by a marker file (JSON) beside them: a run counts as
finished only when its marker records the same commands and a trbc build of the same version and
revision (`trbc --version`). A run of another build or another command is made again."""
import functools
import json
import os
import subprocess
import sys


@functools.lru_cache(maxsize=None)
def trbc_version(trbc):
    """`trbc --version`: the version and the revision of the build."""
    try:
        r = subprocess.run([trbc, "--version"], capture_output=True, text=True)
    except OSError as e:
        sys.exit(f"--trbc {trbc}: {e.strerror}")
    if r.returncode != 0:
        sys.exit(f"--trbc {trbc}: --version exited with {r.returncode}: is it a trbc binary?")
    return r.stdout.strip()


def finished(marker, commands, trbc):
    """The marker's record (with the run's wall_s) when the run is finished, else None (absent,
    unreadable, or made by other commands or another build)."""
    try:
        with open(marker) as f:
            done = json.load(f)
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict):
        return None
    return done if done.get("commands") == commands and done.get("trbc") == trbc_version(trbc) else None


def mark_finished(marker, commands, trbc, wall_s):
    """Writes the marker whole or not at all (a killed script leaves the run unfinished)."""
    with open(marker + ".tmp", "w") as f:
        json.dump({"commands": commands, "trbc": trbc_version(trbc), "wall_s": wall_s}, f)
    os.replace(marker + ".tmp", marker)
