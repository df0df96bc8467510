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


def test_certify_of_the_paper_example_never_imports_jax():
    """Its growth constants and contraction rate are proved by interval branch and bound: the
    sampled estimates that would evaluate the system with jax are never called, so neither the
    batched evaluator nor the jitted Jacobian is built (they are built at their first call)."""
    code = (
        "import sys\n"
        "from drip_cert.bounds.certificate import certify\n"
        f"cert = certify({str(PAPER_4D_SPEC)!r})\n"
        "print(cert.verdict, 'jax' in sys.modules)"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-1] == "False", out.stdout
