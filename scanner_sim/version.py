"""The installed package's version (PEP 440), for --version and the metadata of every output."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("muls-scanner")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"
