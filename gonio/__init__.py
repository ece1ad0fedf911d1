"""gonio: acquisition daemon for fast anisotropic BRDF measurement on rotation-stage rigs."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gonio")
except PackageNotFoundError:  # running from a source tree without an install
    __version__ = "0.0.0+unknown"
