"""tessera.distributed on a local Ray cluster: a distributed render equals the local one bit for
bit, with a plan made once on the driver, and when a worker dies mid-task (Ray retries it);
sequences render one task per frame."""

import os
from pathlib import Path

import numpy as np
import pytest

import tessera

ray = pytest.importorskip("ray")
import tessera.distributed as td  # noqa: E402

SCENES = Path(__file__).resolve().parents[2] / "scenes"
MARBLE = SCENES / "marble.xml"


@pytest.fixture(scope="module")
def cluster():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def same(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))


def local(strategy, spp=5, seed=2, res=32):
    scene = tessera.load(MARBLE, res=res)
    return tessera.render(scene, spp=spp, seed=seed, strategy=strategy)[0]


def test_split_samples():
    assert td.split_samples(7, 3) == [(0, 2), (2, 4), (4, 7)]
    with pytest.raises(ValueError):
        td.split_samples(2, 3)


def test_distributed_render_equals_the_local_one(cluster, tmp_path):
    image, info = td.render(MARBLE, spp=5, seed=2, strategy="outputs", passes=3, defines={"res": 32})
    assert same(image, local("outputs"))
    assert info["passes"] == [(0, 1), (1, 3), (3, 5)]
    assert info["counts"]["samples"] == 32 * 32 * 5
    # The scene and its MaterialX document were shipped, each once.
    assert set(info["files"]) == {"marble.xml", "marble.mtlx"}


def test_sample_passes_times_image_strips_equal_the_local_render(cluster):
    image, info = td.render(MARBLE, spp=5, seed=2, strategy="outputs", passes=2, strips=3, defines={"res": 32})
    assert info["windows"] == [(0, 0, 32, 10), (0, 10, 32, 21), (0, 21, 32, 32)]
    assert same(image, local("outputs"))


def test_auto_plans_once_and_every_pass_uses_the_plan(cluster, tmp_path):
    image, info = td.render(MARBLE, spp=4, seed=1, strategy="auto", passes=2, defines={"res": 32})
    plan = tmp_path / "plan.json"
    plan.write_text(info["plan"])
    assert same(image, local(f"plan:{plan}", spp=4, seed=1))


def test_a_worker_that_dies_is_retried_and_the_image_still_matches(cluster, tmp_path):
    marker = tmp_path / "died-once"
    image, _ = td.render(MARBLE, spp=4, seed=3, strategy="none", passes=2, defines={"res": 32},
                         _fail_marker=str(marker))
    assert marker.exists(), "the first task should have died once"
    assert same(image, local("none", spp=4, seed=3))


def test_frames_render_one_task_each(cluster, tmp_path):
    outs = td.render_frames(MARBLE, [16, 24], str(tmp_path / "f{:02d}.exr"), spp=2, frame_define="res")
    for k, out in zip([16, 24], outs):
        scene = tessera.load(MARBLE, res=k)
        tessera.render(scene, spp=2, out=tmp_path / f"local{k}.exr")
        assert out.read_bytes() == (tmp_path / f"local{k}.exr").read_bytes()
