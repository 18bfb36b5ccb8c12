"""survey: order and chaos in Hamiltonian systems of particles interacting in triplets."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("survey")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0+unknown"
