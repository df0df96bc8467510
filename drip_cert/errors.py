"""Domain exceptions of drip-cert.

Every exception a user can provoke by a mistake in their input is a :class:`DripCertError`;
the command line turns these into a message on stderr and exit status 2 (bad input) or 1
(an assumption that fails), never a traceback; an infeasible L1-DRAC design is a result, not an
exception (``L1Design.feasible``, exit status 1). Each subclass also subclasses the matching
builtin so that generic ``except ValueError`` code keeps working.
"""

from __future__ import annotations


class DripCertError(Exception):
    """Base class of every error drip-cert raises on purpose."""


class SpecError(DripCertError, ValueError):
    """A specification (TOML file, Python arguments, data file) is malformed.

    The message names the field (``section.key[index]``), the offending value and what is
    allowed instead. The command line exits with status 2.
    """

    def __init__(self, message: str, *, field: str | None = None, path: str | None = None) -> None:
        self.field = field
        self.path = path
        where = []
        if path:
            where.append(str(path))
        if field:
            where.append(field)
        prefix = (": ".join(where) + ": ") if where else ""
        super().__init__(prefix + message)


class InputTypeError(DripCertError, TypeError):
    """An argument of the Python API has a type drip-cert does not accept (e.g. ``load_spec(123)``).

    The message says which types are accepted. The command line exits with status 2.
    """


class AssumptionViolation(DripCertError, ArithmeticError):
    """An assumption of the papers fails for the given system (exit status 1)."""


class SolverError(DripCertError, RuntimeError):
    """A numerical solver failed or returned an answer that did not survive re-checking."""


class FingerprintError(DripCertError, ValueError):
    """Recorded data refused: their fingerprint is not the certificate's, or they carry none.

    Data recorded with another policy or L1-DRAC design say nothing about this certificate
    (:mod:`drip_cert.model.fingerprint`). The message names the part that differs (``policy``,
    ``design``) with the recorded and the certified digests. The command line exits with
    status 1 (the data do not validate the certificate), not 2: the file itself is well formed.
    """
