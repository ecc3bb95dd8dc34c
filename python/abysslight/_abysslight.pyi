"""Type stubs of the compiled extension (abysslight's Rust library through PyO3)."""

import os
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]
PhotoArray = Union[
    npt.NDArray[np.uint8], npt.NDArray[np.uint16], npt.NDArray[np.float32], npt.NDArray[np.float64]
]
"""HxWx3 or HxW: uint8/uint16 as stored, or float32/float64 light levels in 0..1 (any byte order)."""

class Scatter:
    """The backscatter image S: the per-pixel temporal median of water-column frames."""

    @staticmethod
    def from_frames(frames: Iterable[PhotoArray]) -> "Scatter":
        """S from water-column frames in memory (HxWx3 or HxW arrays of one shape and dtype)."""
    @staticmethod
    def from_files(files: Union[PathLike, Sequence[PathLike]], memory_mib: int = 2048) -> "Scatter":
        """S from a folder of water-column frames (searched recursively) or a list of files."""
    @staticmethod
    def load(path: PathLike) -> "Scatter":
        """A scatter image saved by a run (--save-scatter) or by Scatter.save."""
    def save(self, path: PathLike) -> None:
        """Save as a 16-bit PNG (what Scatter.load and `correct --scatter` read)."""
    @property
    def image(self) -> npt.NDArray[np.float32]:
        """S as HxWxC float32, stored values scaled to [0, 1]."""
    @property
    def frames(self) -> int:
        """Water-column frames the median was taken over."""
    @property
    def shape(self) -> Tuple[int, int, int]:
        """(height, width, channels)."""

class Mask:
    """Static pixels (overlays, laser dots, vehicle parts) left out of every median."""

    def __init__(self, array: Union[npt.NDArray[np.bool_], npt.NDArray[np.uint8]]) -> None:
        """From an HxW array: True (or non-zero) where pixels are ignored."""
    @staticmethod
    def load(path: PathLike) -> "Mask":
        """A mask image (white: ignored), as --mask reads it."""
    @property
    def array(self) -> npt.NDArray[np.bool_]:
        """HxW, True where ignored."""
    @property
    def count(self) -> int:
        """Pixels ignored."""

class Corrected:
    """One corrected photo, out of Engine.push or Engine.finish."""

    tag: Any
    """What was pushed with the photo."""
    index: int
    """Position among the photos pushed (0-based)."""
    image: PhotoArray
    """The corrected photo: same shape and dtype as the photo pushed."""
    factor: npt.NDArray[np.float32]
    """F at block resolution, in linear light (h x w x C)."""
    health: Dict[str, Any]
    """Health figures and flags of the estimate (as in the run report's frames)."""
    window: Tuple[int, int]
    """(start, stop) of the photos whose median gave F, as Python's range: range(*window). report.json's
    frames[].window lists the first and the last: [start, stop - 1]."""
    altitude: Optional[float]
    """The altitude the photo was pushed with (None: none)."""
    by_altitude: Optional[List[int]]
    """Where its window was chosen by altitude: the indices of the photos it took (None: those window spans)."""

class Engine:
    """The method over a stream of photos in memory; memory bounded by the window.

    Options are the method's options of `abysslight correct` (the config file's keys with '_'): window,
    contamination, risk, downsample, near_window, seafloor_colour (or seafloor_color), factor_floor, transfer,
    method, degree, relative_floor, level_exposures, photo_gain, backscatter_scale, denoise, level_by_light,
    bright_spots, overlaps, laser_paths (and no_level_exposures, no_photo_gain, no_denoise, no_level_by_light,
    no_laser_paths). None given: the
    command's defaults. transfer="auto" (the default) means what the command assumes for a file that declares no
    colour information: linear; give transfer="srgb" for arrays from JPEGs or sRGB-encoded cameras.

    One engine corrects one mission from one thread at a time: a photo after finish(), or a call while another
    thread's call runs, raises RuntimeError.
    """

    def __init__(
        self,
        scatter: Optional[Scatter] = None,
        mask: Optional[Mask] = None,
        by_altitude: bool = False,
        **options: Any,
    ) -> None: ...
    def push(self, photo: PhotoArray, tag: Any = None, altitude: Optional[float] = None) -> List[Corrected]:
        """Give the next photo (and its altitude in metres, from a navigation log); returns the photos whose window
        became complete, in order (GIL released). With altitudes, where the altitude swings along the track, windows
        are chosen among the photos lit from the nearest heights. Windows by altitude start with the first photo:
        an altitude after a first photo without one is a ValueError unless the engine was made with
        by_altitude=True."""
    def finish(self) -> List[Corrected]:
        """Every photo still waiting, corrected with the window shifted back from the end; the mission's end."""
    @property
    def window(self) -> Optional[int]: ...
    @property
    def downsample(self) -> int: ...
    @property
    def transfer(self) -> str: ...
    @property
    def method(self) -> str: ...
    @property
    def waiting(self) -> int: ...

def correct_arrays(
    photos: Iterable[PhotoArray],
    water_column: Union[None, Scatter, Iterable[PhotoArray]] = None,
    mask: Optional[Mask] = None,
    altitudes: Optional[Sequence[Optional[float]]] = None,
    **options: Any,
) -> List[PhotoArray]:
    """Correct a list of photos in one call through an Engine (the Engine's options); the corrected arrays in
    order, each of its photo's shape and dtype. water_column: water-column frames, a Scatter, or None (S = 0).
    altitudes: each photo's altitude in metres (a navigation log; None where it has none), for windows chosen by
    altitude."""

def correct(progress: Optional[Callable[[int, int, str, bool], Any]] = None, **options: Any) -> Dict[str, Any]:
    """abysslight correct: the run report; with cruise=, {"dives": {name: report}, "failed": {name: message}}."""
def run_cli(argv: List[str]) -> int:
    """Run the abysslight command with argv (argv[0] is the program's name); returns its exit status."""

def read(path: PathLike) -> PhotoArray:
    """Decode a photo file as a run decodes it (HxWx3 or HxW, uint8 or uint16)."""

def simulate(
    frames: int = 30,
    water_column: int = 15,
    width: int = 320,
    height: int = 240,
    seed: int = 1,
    contamination: float = 0.2,
    bit_depth: int = 8,
    encode: str = "linear",
    noise: float = 1.0,
) -> Dict[str, Any]:
    """A simulated dive in memory: {"survey": [arrays], "water_column": [arrays], "albedo": [float32 arrays],
    "transfer": the curve the photos were encoded with}. The ranges of `abysslight simulate` (ValueError with
    its messages); MemoryError when the dive cannot be held in memory."""

def evaluate(
    sets: Sequence[Tuple[str, PathLike]],
    truth: Optional[PathLike] = None,
    placements: Optional[PathLike] = None,
    cell: float = 8.0,
    transfer: Optional[str] = None,
    mask: Optional[PathLike] = None,
) -> Dict[str, Any]:
    """Score folders of corrected photos, as `abysslight evaluate` does; sets: (label, folder) pairs."""
