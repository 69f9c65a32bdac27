"""tessera from Python: load a scene once, render it into NumPy, trace footprints, bake MaterialX.

>>> import tessera
>>> scene = tessera.load("scene.xml", res=128)       # -D res=128
>>> image, stats = tessera.render(scene, spp=16, strategy="auto")
>>> image.shape, image.dtype                          # (128, 128, 3) float32, linear RGB
>>> stats["counts"]["samples"]

A render is ``tessera render``'s, bit for bit: the keyword arguments are spelled as its flags.
Errors are :class:`TesseraError` with tessera's own message (file and line where known).
"""

from __future__ import annotations

import json
import operator
import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._tessera import Scene, TesseraError, __version__
from ._tessera import bake as _bake
from ._tessera import load as _load
from ._tessera import merge as _merge
from ._tessera import save_image

__all__ = ["Scene", "TesseraError", "load", "render", "plan", "merge", "save_image", "footprint", "bake", "__version__"]

PathLike = Union[str, "os.PathLike[str]"]


def _define_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


def load(path: Optional[PathLike] = None, **defines: Any) -> Scene:
    """Loads a Mitsuba 3 XML scene (the embedded demo scene when ``path`` is None).

    Keyword arguments override the scene's ``<default>`` values, as ``-D name=value`` does.
    """
    return _load(None if path is None else os.fspath(path), [(k, _define_value(v)) for k, v in defines.items()])


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


_INTEGER_FLAGS = ("spp", "seed", "threads")


def _flags(**values: Any) -> List[str]:
    """``tessera render``'s flags for the keyword arguments that are not None (integers checked)."""
    opts: List[str] = []
    for name, value in values.items():
        if name in _INTEGER_FLAGS:
            value = _int(name, value)
        if value is not None:
            opts += [_flag(name), os.fspath(value) if isinstance(value, os.PathLike) else str(value)]
    return opts


def _int(name: str, value: Any) -> Optional[int]:
    """``value`` as an int (None stays None); anything else is a TypeError naming ``name``."""
    if value is None:
        return None
    try:
        return operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}") from None


def render(
    scene: Scene,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    strategy: str = "none",
    budget_mb: Optional[float] = None,
    threads: Optional[int] = None,
    *,
    samples: Optional[Tuple[int, int]] = None,
    crop: Optional[Tuple[int, int, int, int]] = None,
    footprint: Optional[str] = None,
    filter_scale: Union[float, str, None] = None,
    free_textures: bool = False,
    profile_share: Optional[float] = None,
    strict: bool = False,
    out: Optional[PathLike] = None,
    stats_json: Optional[PathLike] = None,
    report: Optional[PathLike] = None,
    progress: bool = False,
) -> Tuple[np.ndarray, Dict[str, Any]]:
    """Renders ``scene``; returns the image (height × width × 3 float32, linear RGB, a view of
    the renderer's own buffer) and the stats (the ``tessera.stats/1`` document as a dict).

    ``samples=(a, b)`` takes sample indices a to b−1 of a render of ``spp`` and ``crop=(x0, y0,
    x1, y1)`` a window; either writes a pass file to ``out`` (an ``.exr``) for ``tessera merge``.
    Without ``out`` nothing is written (but ``stats_json`` and ``report`` when given).
    ``progress`` shows tessera's progress bar and summary on a terminal.
    """
    opts = _flags(
        spp=spp,
        seed=seed,
        budget_mb=budget_mb,
        threads=threads,
        footprint=footprint,
        filter_scale=filter_scale,
        profile_share=profile_share,
        out=out,
        stats_json=stats_json,
        report=report,
    )
    opts += ["--strategy", str(strategy)]
    if samples is not None:
        a, b = samples
        opts += ["--samples", f"{int(a)}..{int(b)}"]
    if crop is not None:
        opts += ["--crop", ",".join(str(int(c)) for c in crop)]
    if free_textures:
        opts.append("--free-textures")
    if strict:
        opts.append("--strict")
    if not progress:
        opts.append("--quiet")
    image, stats = scene.render(opts)
    return image, json.loads(stats)


def plan(
    scene: Scene,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    budget_mb: Optional[float] = None,
    threads: Optional[int] = None,
    *,
    profile_share: Optional[float] = None,
    footprint: Optional[str] = None,
    filter_scale: Union[float, str, None] = None,
) -> str:
    """Profiles and plans as ``strategy="auto"`` does for a render with these settings; returns
    the plan file (``tessera.plan/1``) as JSON text. Written to a file, it is the strategy
    ``plan:FILE`` of renders that must cache the same nodes (sample passes, other machines)."""
    opts = _flags(
        spp=spp,
        seed=seed,
        budget_mb=budget_mb,
        threads=threads,
        profile_share=profile_share,
        footprint=footprint,
        filter_scale=filter_scale,
    )
    return scene.plan(opts + ["--quiet"])


def merge(passes: Sequence[PathLike], out: Optional[PathLike] = None) -> Tuple[np.ndarray, Dict[str, Any]]:
    """Merges the pass files of one split render (``render(..., samples=..., crop=..., out=...)``)
    into its image, bit for bit the unsplit render's, as ``tessera merge`` does; returns the image
    and the passes' summed counts. With ``out`` (.exr or .png), also writes it."""
    image, counts = _merge([os.fspath(p) for p in passes])
    if out is not None:
        save_image(image, os.fspath(out))
    return image, json.loads(counts)


def footprint(
    scene: Scene,
    pixel: Tuple[int, int],
    seed: Optional[int] = None,
    estimator: str = "covariance",
    density: float = 1024.0,
) -> Dict[str, Any]:
    """Traces sample 0 of ``pixel`` = (x, y) as a render does and returns each vertex's
    footprint (the ``tessera.footprint/1`` document ``tessera footprint --json`` prints)."""
    x, y = pixel
    return json.loads(scene.footprint(int(x), int(y), seed, estimator, float(density)))


def bake(
    document: PathLike,
    element: str,
    res: int,
    res_y: Optional[int] = None,
    uv_min: Tuple[float, float] = (0.0, 0.0),
    uv_max: Tuple[float, float] = (1.0, 1.0),
    filter: str = "point",
    orientation: str = "materialx",
    search_paths: Iterable[PathLike] = (),
    threads: Optional[int] = None,
) -> Tuple[np.ndarray, Sequence[str]]:
    """Evaluates a MaterialX output (``nodegraph/output``) or material input on a grid of texels
    over a uv rectangle, as ``tessera bake`` does; returns rows × columns × channels float32
    (top row first) and the channel names (``Y``; ``R, G``; ``R, G, B``; ``R, G, B, A``)."""
    opts = ["--element", element, "--res", str(int(res))]
    if res_y is not None:
        opts += ["--res-y", str(int(res_y))]
    opts += ["--uv-min", f"{uv_min[0]},{uv_min[1]}", "--uv-max", f"{uv_max[0]},{uv_max[1]}"]
    opts += ["--filter", filter, "--orientation", orientation]
    for p in search_paths:
        opts += ["--search-path", os.fspath(p)]
    if threads is not None:
        opts += ["--threads", str(int(threads))]
    return _bake(os.fspath(document), opts)
