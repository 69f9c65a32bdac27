"""Type stubs of tessera's native module (crates/python)."""

from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

class TesseraError(Exception):
    """An error tessera reports: bad input, a failed render."""

class Scene:
    """A loaded scene (see ``tessera.load``)."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def spp(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def path(self) -> Optional[Path]: ...
    @property
    def defines(self) -> List[Tuple[str, str]]: ...
    @property
    def files(self) -> List[Path]:
        """Every file the scene was built from, the scene file first."""
    def plan(self, options: Sequence[str]) -> str:
        """Profiles and plans as ``--strategy auto`` would; returns the plan file's JSON."""
    def render(self, options: Sequence[str]) -> Tuple[npt.NDArray[np.float32], str]:
        """Renders with ``tessera render``'s flags; returns the image and the stats as JSON."""
    def footprint(self, x: int, y: int, seed: Optional[int], estimator: str, density: float) -> str:
        """One camera path's footprints as JSON (``tessera.footprint/1``)."""

def load(path: Optional[str], defines: Sequence[Tuple[str, str]]) -> Scene: ...
def bake(document: str, options: Sequence[str]) -> Tuple[npt.NDArray[np.float32], List[str]]: ...
def merge(passes: Sequence[str]) -> Tuple[npt.NDArray[np.float32], str]: ...
def save_image(image: npt.NDArray[np.float32], path: str) -> None: ...
