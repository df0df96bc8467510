"""Private numerics: outward rounding, interval arithmetic, statistics and atomic file writes.

Used by every layer above; imports only :mod:`drip_cert.errors` and :mod:`drip_cert.provenance`.
"""
