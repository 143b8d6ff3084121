"""Two versions of softbody timed in one run: each in a worker process of its own, called
in alternation, so both see the same machine load (ratios are what a shared machine
measures reliably).

``Version("this")`` imports this checkout's package; ``Version("baseline", SRC)`` imports
another version's sources, e.g. a checkout of an earlier commit made with ``git worktree
add /tmp/old COMMIT`` whose core was built in place (``python tools/build_core.py`` there).
A worker runs functions of this checkout's benchmark modules (``"engine:rate"``) with
JSON arguments and answers JSON, so the same measurement code times both versions; a
function sees which version it runs in through ``softbody_version()``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

HERE = Path(__file__).resolve().parent
WORKER = r"""
import importlib, json, os, sys
sys.path.insert(0, os.environ["SOFTBODY_BENCH_DIR"])
for line in sys.stdin:
    call = json.loads(line)
    module, function = call["function"].split(":")
    try:
        result = {"ok": getattr(importlib.import_module(module), function)(**call["kwargs"])}
    except Exception as error:  # the caller raises it, with this process's message
        result = {"error": f"{type(error).__name__}: {error}"}
    print(json.dumps(result), flush=True)
"""


def softbody_version() -> str:
    """The name of the version this worker runs (``"this"`` outside a worker)."""
    return os.environ.get("SOFTBODY_BENCH_VERSION", "this")


class Version:
    """A worker process running one version of softbody (see the module docstring)."""

    def __init__(self, name: str, source: Path | None = None):
        self.name = name
        env = {**os.environ, "SOFTBODY_BENCH_DIR": str(HERE), "SOFTBODY_BENCH_VERSION": name}
        flags = []
        if source is not None:
            source = Path(source).resolve()
            if not (source / "softbody").is_dir():
                raise SystemExit(f"{source} holds no softbody package (give a checkout's src)")
            # -S: no site hooks, so an editable install's import redirect cannot swap
            # this version back in; the environment's packages come through PYTHONPATH
            site = sysconfig.get_paths()
            env["PYTHONPATH"] = os.pathsep.join([str(source), site["purelib"], site["platlib"]])
            flags = ["-S"]
        self._process = subprocess.Popen(
            [sys.executable, *flags, "-c", WORKER], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, env=env, text=True,
        )  # fmt: skip

    def call(self, function: str, **kwargs):
        """``module:function(**kwargs)`` in the worker; its JSON result."""
        self._process.stdin.write(json.dumps({"function": function, "kwargs": kwargs}) + "\n")
        self._process.stdin.flush()
        line = self._process.stdout.readline()
        if not line:
            raise RuntimeError(f"the {self.name} worker exited")
        answer = json.loads(line)
        if "error" in answer:
            raise RuntimeError(f"{self.name}: {answer['error']}")
        return answer["ok"]

    def close(self) -> None:
        self._process.stdin.close()
        self._process.wait(timeout=60)


def versions(baseline: Path | None) -> list[Version]:
    """This checkout's worker, and the baseline's when its sources are given."""
    out = [Version("this")]
    if baseline is not None:
        out.append(Version("baseline", baseline))
    return out
