"""What a `certify` imports (issue 26: the CPU a user pays before and after the mathematics).

jax (0.3 CPU-s to import) and scipy (0.13 CPU-s for ``scipy.special``) are imported where they
are used, not on the import path of the certificate: a certify whose bounds are proved by
interval arithmetic (the DRIP paper's example) never imports jax at all.
"""

from __future__ import annotations

import subprocess
import sys

from tests.helpers import PAPER_4D_SPEC, ROOT

#: packages that `import drip_cert.bounds.certificate` must not import (issue 26)
NOT_ON_THE_IMPORT_PATH = ("jax", "jaxlib", "scipy")


def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )


def test_the_certificate_imports_neither_jax_nor_scipy():
    code = (
        "import sys, drip_cert.bounds.certificate\n"
        f"print(','.join(m for m in {NOT_ON_THE_IMPORT_PATH!r} if m in sys.modules))"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"imported by the certificate: {out.stdout}"


def test_certify_of_the_paper_example_never_imports_jax_scipy_or_clarabel():
    """Its growth constants and contraction rate are proved by interval branch and bound: the
    sampled estimates that would evaluate the system with jax are never called, so neither the
    batched evaluator nor the jitted Jacobian is built (they are built at their first call);
    its expert's Euclidean rate already meets the spectral abscissa, so the metric search's
    bracket is closed and no SDP is built (scipy.sparse, clarabel: at the first solve)."""
    code = (
        "import sys\n"
        "from drip_cert.bounds.certificate import certify\n"
        f"cert = certify({str(PAPER_4D_SPEC)!r})\n"
        "print(cert.verdict, *(m in sys.modules for m in ('jax', 'scipy', 'clarabel')))"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-3:] == ["False", "False", "False"], out.stdout


# ------------------------------------------------------------------ the command's process exit
def _console(*argv: str, before: str = "") -> subprocess.CompletedProcess[str]:
    """Run the ``drip-cert`` console script of ``pyproject.toml`` as pip's generated script
    does (``sys.exit(entry())``), in a child whose ``__main__`` holds an object that writes
    ``TEARDOWN`` when the interpreter frees it and an ``atexit`` handler that writes ``ATEXIT``
    (both on stderr); ``before`` runs first."""
    import tomllib

    entry = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, func = entry["drip-cert"].split(":")
    code = (
        "import atexit, os, sys\n"
        "class Sentinel:\n"
        "    def __del__(self, write=os.write):\n"
        "        write(2, b'TEARDOWN\\n')\n"
        "kept = Sentinel()\n"
        "atexit.register(os.write, 2, b'ATEXIT\\n')\n"
        f"{before}\n"
        f"from {module} import {func} as entry\n"
        f"sys.argv = ['drip-cert', *{list(argv)!r}]\n"
        "sys.exit(entry())\n"
    )
    return _python(code)


def test_the_command_exits_after_its_output_without_tearing_the_interpreter_down(tmp_path):
    """A `certify` that succeeds: exit 0, its JSON on stdout whole, the file it writes whole,
    the atexit handlers run; the interpreter's teardown (0.2 CPU-s, issue 26) is skipped."""
    import json
    import tomllib

    out_file = tmp_path / "l1.toml"
    out = _console("certify", str(PAPER_4D_SPEC), "--json", "--export-l1-constants", str(out_file))
    assert out.returncode == 0, out.stderr
    cert = json.loads(out.stdout)
    assert cert["accepted"]["exit_status"] == 0
    assert tomllib.loads(out_file.read_text())  # the whole file: a partial one does not parse
    assert "ATEXIT" in out.stderr.splitlines()
    assert "TEARDOWN" not in out.stderr


def test_a_user_error_exits_2_with_its_whole_message(tmp_path):
    missing = tmp_path / "missing.toml"
    out = _console("certify", str(missing), "--json")
    assert out.returncode == 2, out.stderr
    assert out.stdout == ""
    lines = out.stderr.splitlines()
    assert lines[0].startswith("drip-cert: error: ") and str(missing) in lines[0], out.stderr
    assert "Traceback" not in out.stderr
    assert lines[1:] == ["ATEXIT"]


def test_a_thread_still_running_is_joined_before_the_exit(tmp_path):
    """A non-daemon thread alive after the command (none of drip-cert's: its pools are closed
    before it returns) makes the interpreter exit the normal way, which waits for it. The
    thread writes only once the main thread has finished, so an ``os._exit`` would lose it."""
    before = (
        "import threading\n"
        "def late():\n"
        "    threading.main_thread().join()\n"
        "    os.write(2, b'THREAD\\n')\n"
        "threading.Thread(target=late).start()"
    )
    out = _console("certify", str(tmp_path / "missing.toml"), before=before)
    assert out.returncode == 2, out.stderr
    assert "THREAD" in out.stderr.splitlines()


def test_a_profiled_command_still_writes_its_profile(tmp_path):
    """Under cProfile (a profiler writes its results at the normal exit) the command exits the
    normal way: ``python -m cProfile -o FILE -m drip_cert.cli ...`` leaves FILE."""
    import pstats

    prof = tmp_path / "cli.prof"
    out = subprocess.run(
        [sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "drip_cert.cli", "certify"]
        + [str(tmp_path / "missing.toml")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert "drip-cert: error: " in out.stderr  # cProfile drops the exit status: not checked
    assert pstats.Stats(str(prof)).total_calls > 0
