"""leg-env: the planar floating-base leg as an exact, fast Gymnasium environment."""
from .params import LegParams

__all__ = ["LegParams"]
__version__ = "0.1.0"
