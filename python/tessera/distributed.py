"""Renders across machines with Ray (``pip install ray``): sample passes of one image, or one task
per frame of a sequence.

>>> import ray, tessera.distributed as td
>>> ray.init()                                   # or ray.init(address="auto") on a cluster
>>> image, info = td.render("scene.xml", spp=256, strategy="auto", passes=8)

How the work is split:

- The driver loads the scene once, and for ``strategy="auto"`` profiles and plans once; every
  task then renders with that plan (``plan:FILE``), so that all passes cache the same nodes.
- Every file the scene was built from (``Scene.files``: the scene, its includes, meshes, images,
  MaterialX documents and their images), and the plan, goes into Ray's object store once per
  distinct content (keyed by its SHA-256). A task receives the manifest (relative path → hash)
  and the object references; Ray moves each object to a node once, and the node's tasks lay the
  files out under a folder named after the manifest's hash, written once and reused.
- A task renders sample indices ``a..b`` of every pixel (``samples=(a, b)``) and returns the pass
  file's bytes; the driver merges them (``tessera.merge``), bit for bit the single render's image.
  Tile caches live in each task's process: a pass fills the tiles it reads.
- A task whose worker dies is retried by Ray (``max_retries``); a pass is a pure function of its
  inputs, so the retried result, and the merged image, are the same.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

import tessera

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["render", "render_frames", "split_samples"]


def _ray():
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("tessera.distributed needs Ray: pip install ray") from e
    if not ray.is_initialized():
        ray.init()
    return ray


def split_samples(spp: int, passes: int) -> List[Tuple[int, int]]:
    """``passes`` contiguous sample ranges covering ``0..spp``, as even as whole samples allow."""
    if not (1 <= passes <= spp):
        raise ValueError(f"passes must be between 1 and spp ({spp}), got {passes}")
    cuts = [spp * i // passes for i in range(passes + 1)]
    return list(zip(cuts[:-1], cuts[1:]))


class _Shipment:
    """The scene's files (and extra blobs) in the object store, each distinct content once."""

    def __init__(self, ray, files: Sequence[Path], extra: Dict[str, bytes]):
        files = [Path(f).resolve() for f in files]
        self.root = Path(os.path.commonpath([str(f.parent) for f in files])) if files else Path(".")
        self.manifest: Dict[str, str] = {}
        self.blobs: Dict[str, Any] = {}
        for rel, data in [(str(f.relative_to(self.root)), f.read_bytes()) for f in files] + list(extra.items()):
            digest = hashlib.sha256(data).hexdigest()
            self.manifest[rel] = digest
            if digest not in self.blobs:
                self.blobs[digest] = ray.put(data)
        self.key = hashlib.sha256(repr(sorted(self.manifest.items())).encode()).hexdigest()[:16]

    def relative(self, path: PathLike) -> str:
        return str(Path(path).resolve().relative_to(self.root))


def _materialise(manifest: Dict[str, str], blobs: Dict[str, Any], key: str) -> Path:
    """Lays the shipped files out on this node (once per manifest) and returns their root."""
    import ray

    root = Path(tempfile.gettempdir()) / "tessera-ray" / key
    for rel, digest in manifest.items():
        path = root / rel
        if path.is_file():
            continue
        data = ray.get(blobs[digest])
        if hashlib.sha256(data).hexdigest() != digest:
            raise tessera.TesseraError(f"{rel}: the shipped file does not match its hash")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    return root


def _render_part(manifest, blobs, key, scene_rel, defines, options, out_name, fail_marker=None) -> bytes:
    """A Ray task: lays out the shipped files, renders with ``options`` (a pass, a window or a
    whole frame) into ``out_name`` and returns the file's bytes."""
    if fail_marker is not None and not os.path.exists(fail_marker):
        # Testing hook: the first attempt dies mid-task, as a lost worker would.
        Path(fail_marker).write_text("died once\n")
        os._exit(1)
    root = _materialise(manifest, blobs, key)
    scene = tessera.load(root / scene_rel, **defines)
    options = dict(options)
    if options.get("strategy", "").startswith("plan:"):
        options["strategy"] = "plan:" + str(root / options["strategy"][5:])
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / out_name
        tessera.render(scene, out=out, **options)
        return out.read_bytes()


def render(
    scene_path: PathLike,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    strategy: str = "auto",
    passes: int = 2,
    *,
    strips: int = 1,
    defines: Optional[Dict[str, Any]] = None,
    budget_mb: Optional[float] = None,
    threads: Optional[int] = None,
    profile_share: Optional[float] = None,
    num_cpus: float = 1,
    max_retries: int = 3,
    out: Optional[PathLike] = None,
    keep_passes: Optional[PathLike] = None,
    _fail_marker: Optional[str] = None,
) -> Tuple[np.ndarray, Dict[str, Any]]:
    """Renders ``scene_path`` as Ray tasks, ``passes`` contiguous sample ranges times ``strips``
    horizontal bands of the image, and merges them: bit for bit the image ``tessera.render`` makes
    in one process with the same plan.

    ``strategy="auto"`` profiles and plans once on the driver; other strategies are passed on.
    Each task takes ``num_cpus`` of Ray's CPUs and renders on ``threads`` threads (default: as
    many as ``num_cpus``). Returns the image and ``{"passes", "plan", "counts", "files"}``;
    ``out`` also writes the image, ``keep_passes`` keeps the pass files in that folder.
    """
    ray = _ray()
    defines = {k: str(v) for k, v in (defines or {}).items()}
    scene = tessera.load(scene_path, **defines)
    spp = scene.spp if spp is None else spp
    seed = scene.seed if seed is None else seed
    threads = max(1, int(num_cpus)) if threads is None else threads
    options: Dict[str, Any] = {"spp": spp, "seed": seed, "threads": threads}
    if budget_mb is not None:
        options["budget_mb"] = budget_mb
    extra: Dict[str, bytes] = {}
    plan_json = None
    if strategy == "auto":
        plan_json = tessera.plan(scene, spp=spp, seed=seed, budget_mb=budget_mb, profile_share=profile_share)
        extra[".tessera/plan.json"] = plan_json.encode()
        options["strategy"] = "plan:.tessera/plan.json"
    elif strategy.startswith("plan:"):
        extra[".tessera/plan.json"] = Path(strategy[5:]).read_bytes()
        options["strategy"] = "plan:.tessera/plan.json"
    else:
        options["strategy"] = strategy
    files = list(scene.files)
    if not files:
        raise tessera.TesseraError("the embedded demo scene has no files to ship; give a scene file")
    shipment = _Shipment(ray, files, extra)
    task = ray.remote(num_cpus=num_cpus, max_retries=max_retries)(_render_part)
    ranges = split_samples(spp, passes)
    if not (1 <= strips <= scene.height):
        raise ValueError(f"strips must be between 1 and the image height ({scene.height}), got {strips}")
    rows = [scene.height * i // strips for i in range(strips + 1)]
    parts = [
        ((a, b), (0, y0, scene.width, y1), f"pass-{a}-{b}-rows-{y0}-{y1}.exr")
        for (a, b) in ranges
        for y0, y1 in zip(rows[:-1], rows[1:])
    ]
    refs = [
        task.remote(
            shipment.manifest,
            shipment.blobs,
            shipment.key,
            shipment.relative(scene_path),
            defines,
            dict(options, samples=r, crop=window if strips > 1 else None),
            name,
            _fail_marker if i == 0 else None,
        )
        for i, (r, window, name) in enumerate(parts)
    ]
    blobs = ray.get(refs)
    folder = Path(keep_passes) if keep_passes is not None else Path(tempfile.mkdtemp(prefix="tessera-passes-"))
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for (_, _, name), data in zip(parts, blobs):
        p = folder / name
        p.write_bytes(data)
        paths.append(p)
    try:
        image, counts = tessera.merge(paths, out=out)
    finally:
        if keep_passes is None:
            for p in paths:
                p.unlink(missing_ok=True)
            folder.rmdir()
    info = {
        "passes": ranges,
        "windows": [w for _, w, _ in parts[:strips]],
        "plan": plan_json,
        "counts": counts,
        "files": {rel: digest for rel, digest in shipment.manifest.items()},
    }
    return image, info


def render_frames(
    scene_path: PathLike,
    frames: Sequence[int],
    out_pattern: str = "frame_{:04d}.exr",
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    strategy: str = "none",
    *,
    defines: Optional[Dict[str, Any]] = None,
    frame_define: str = "frame",
    budget_mb: Optional[float] = None,
    num_cpus: float = 1,
    max_retries: int = 3,
) -> List[Path]:
    """Renders a sequence, one Ray task per frame: frame ``k`` is the scene with
    ``-D {frame_define}=k``, written to ``out_pattern.format(k)`` (.exr or .png). Each task
    plans for itself with ``strategy="auto"`` (frames differ). Returns the files written."""
    ray = _ray()
    defines = {k: str(v) for k, v in (defines or {}).items()}
    first = tessera.load(scene_path, **dict(defines, **{frame_define: str(frames[0])}))
    shipment = _Shipment(ray, list(first.files), {})
    task = ray.remote(num_cpus=num_cpus, max_retries=max_retries)(_render_part)
    options: Dict[str, Any] = {"strategy": strategy, "threads": max(1, int(num_cpus))}
    for name, value in [("spp", spp), ("seed", seed), ("budget_mb", budget_mb)]:
        if value is not None:
            options[name] = value
    outs = [Path(out_pattern.format(k)) for k in frames]
    refs = [
        task.remote(
            shipment.manifest,
            shipment.blobs,
            shipment.key,
            shipment.relative(scene_path),
            dict(defines, **{frame_define: str(k)}),
            options,
            "frame" + out.suffix,
        )
        for k, out in zip(frames, outs)
    ]
    for out, data in zip(outs, ray.get(refs)):
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, out)
    return outs
