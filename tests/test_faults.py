"""Device faults: a Vulkan device lost or out of memory mid-run, or a scene whose buffers do not
fit the device, stops the run with one clear message and a suggestion; the last checkpoint is
intact and the run resumes from it (on the same device: bitwise; on numba: with a note).

Loss and memory exhaustion mid-run cannot be provoked on purpose, so vkQueueSubmit is
replaced in this process by one that fails after some submissions, as a driver does. A
buffer beyond the device's maxStorageBufferRange is provoked for real (lavapipe: 128 MiB).
"""
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import vulkan_or_skip
from sphcore.cli import main
from sphcore.simulation import CHECKPOINT

# 6 x 6 = 36 particles falling; a checkpoint every 10 steps, a snapshot every 5
TOML = """\
name = "tiny"
[physics]
model = "graphics"
[fluid]
spacing = 0.05
blocks = [{ min = [0.3, 0.4], max = [0.6, 0.7] }]
[time]
dt = 1e-3
steps = 40
output_every = 5
checkpoint_every = 10
"""


def one_line_error(capsys, argv):
    assert main([str(a) for a in argv]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line.split("\r")[-1] for line in err.strip().splitlines()]
    assert lines[-1].startswith("sphcore: error: ") and err.count("sphcore:") == 1, err
    return lines[-1]


def fail_once_checkpointed(monkeypatch, out_dir, step, error):
    """Make vkQueueSubmit raise `error` once out_dir holds a checkpoint at `step` or later; the
    device then behaves as a lost one: waiting on it raises VK_ERROR_DEVICE_LOST too."""
    import vulkan
    real_submit, real_wait = vulkan.vkQueueSubmit, vulkan.vkDeviceWaitIdle
    failed = []

    def submit(*args):
        if failed or (out_dir / CHECKPOINT).exists() and int(np.load(out_dir / CHECKPOINT)["step"]) >= step:
            failed.append(1)
            raise error()
        return real_submit(*args)

    def wait_idle(device):
        if failed:
            raise vulkan.VkErrorDeviceLost()
        return real_wait(device)

    monkeypatch.setattr(vulkan, "vkQueueSubmit", submit)
    monkeypatch.setattr(vulkan, "vkDeviceWaitIdle", wait_idle)


@pytest.mark.parametrize("error, says", [("VkErrorDeviceLost", "the Vulkan device was lost"),
                                         ("VkErrorOutOfDeviceMemory", "out of device memory while running")],
                         ids=["device-lost", "out-of-memory"])
def test_fault_mid_run_keeps_the_checkpoint(tmp_path, capsys, monkeypatch, error, says):
    vulkan_or_skip()
    import vulkan
    scene_file = tmp_path / "tiny.toml"
    scene_file.write_text(TOML)
    out_dir = tmp_path / "run"
    with monkeypatch.context() as patch:
        fail_once_checkpointed(patch, out_dir, 20, getattr(vulkan, error))
        message = one_line_error(capsys, ["run", scene_file, "--backend", "vulkan", "--out", out_dir])
    assert says in message and "--backend numba" in message
    assert f"the checkpoint at step 20 is intact: continue with `sphcore run --resume {out_dir}`" in message
    assert not (out_dir / "final.npz").exists() and not list(out_dir.glob(".*tmp*"))
    assert int(np.load(out_dir / CHECKPOINT)["step"]) == 20
    listed = [ds.get("file") for ds in ET.parse(out_dir / "tiny.pvd").getroot().iter("DataSet")]
    assert listed == [f"tiny_{s:07d}.vtp" for s in (0, 5, 10, 15, 20)]

    # on the CPU: the same state continues, with a note that the bits will differ
    shutil.copytree(out_dir, tmp_path / "on_numba")
    assert main(["run", "--resume", str(tmp_path / "on_numba"), "--backend", "numba"]) == 0
    err = capsys.readouterr().err
    assert "sphcore: note:" in err and "written by vulkan on" in err and "not be bitwise" in err
    assert int(np.load(tmp_path / "on_numba" / "final.npz")["step"]) == 40

    # on the device again (the fault gone): the same bytes as a run that never failed
    assert main(["run", "--resume", str(out_dir)]) == 0
    assert main(["run", str(scene_file), "--backend", "vulkan", "--out", str(tmp_path / "reference")]) == 0
    capsys.readouterr()
    assert (out_dir / "final.npz").read_bytes() == (tmp_path / "reference" / "final.npz").read_bytes()


def test_buffer_beyond_the_device_limit(tmp_path, capsys):
    """A few particles in a box of 36 million cells: the neighbour grid's pyramid needs 156 MiB,
    more than lavapipe's largest storage buffer (128 MiB)."""
    vulkan_or_skip()
    from sphcore.vk_runner import Context
    with Context() as ctx:
        limit, name = ctx.max_storage_buffer_range, ctx.device_name
    cells = 6000 * 6000
    if cells * 4 * 8 // 7 <= limit:
        pytest.skip(f"{name} takes storage buffers of {limit / 2**20:.0f} MiB: no scene's grid is that large")
    scene_file = tmp_path / "huge_box.toml"
    scene_file.write_text(TOML.replace("spacing = 0.05", "spacing = 0.005").replace("max = [0.6, 0.7]", "max = [0.32, 0.42]")
                          + "[domain]\nbox_max = [60.0, 60.0]\n")  # h = 0.01 m: 6000 x 6000 cells
    message = one_line_error(capsys, ["run", scene_file, "--backend", "vulkan", "--out", tmp_path / "out"])
    assert "out of device memory: buffer 'cell_pyramid' needs" in message
    assert f"largest storage buffer ({limit / 2**20:.1f} MiB on {name})" in message
    assert "coarser grid" in message and "--backend numba" in message
    assert not (tmp_path / "out" / "final.npz").exists() and not (tmp_path / "out" / CHECKPOINT).exists()
