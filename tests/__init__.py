"""The test suite: a package, so that every module imports shared pieces from tests.helpers."""
