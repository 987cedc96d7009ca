"""Volume files (files/volume_io.py): the .vol writer is Mitsuba's format byte for byte, .npz round-trips,
and a bad .npz is refused with a message naming the file (the CLI's messages: tests/test_compare_cli.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.volume import test_volume
from mitsuba_platonic.files.volume_io import (load_volume, read_npz, save_volume, to_mitsuba_grid, write_npz,
                                        write_vol)


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_write_vol_writes_the_bytes_mitsuba_writes(tmp_path, channels):
    from mitsuba_platonic.render.variant import ensure_variant

    mi = ensure_variant()
    volume = torch.rand(channels, 5, 5, 5)
    ours = write_vol(volume, tmp_path / "ours.vol")
    mi.VolumeGrid(to_mitsuba_grid(volume).contiguous().numpy()).write(str(tmp_path / "mitsuba.vol"))
    assert ours.read_bytes() == (tmp_path / "mitsuba.vol").read_bytes()
    read = np.array(mi.VolumeGrid(str(ours)))                       # and Mitsuba reads it back
    np.testing.assert_array_equal(read.reshape(5, 5, 5, channels), to_mitsuba_grid(volume).numpy())


def test_save_volume_writes_npz_and_vol_that_read_back(tmp_path):
    volume = test_volume(6, "figure", "ea")[0]
    paths = save_volume(volume, tmp_path / "sub" / "shot.v1")
    assert [p.name for p in paths] == ["shot.v1.npz", "shot.v1.vol"]          # the stem keeps its dots
    assert torch.equal(read_npz(paths[0]), volume[None])
    assert paths[1].stat().st_size == 48 + 4 * volume.numel()
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["shot.v1.npz", "shot.v1.vol"]  # no temporary


def test_read_npz_takes_a_batch_of_one_and_density_only(tmp_path):
    density = test_volume(4, "cloud", "vh")                         # (1, 1, N, N, N)
    np.savez(tmp_path / "d.npz", volume=density.numpy())
    assert torch.equal(read_npz(tmp_path / "d.npz"), density)
    write_npz(density[0], tmp_path / "w.npz")
    assert torch.equal(read_npz(tmp_path / "w.npz"), density)


def test_a_bad_npz_is_a_user_error_naming_the_file(tmp_path):
    path = tmp_path / "bad.npz"
    np.savez(path, volume=np.full((4, 3, 3, 3), 2.0, np.float32))
    with pytest.raises(UserError, match=r"bad\.npz.*values must lie in \[0, 1\]"):
        read_npz(path)
    with pytest.raises(UserError, match="does not exist"):
        read_npz(tmp_path / "missing.npz")


def test_load_volume_reads_builtins_and_files(tmp_path):
    assert load_volume("builtin:cloud", 8).shape == (1, 4, 8, 8, 8)
    save_volume(test_volume(4, "figure", "ea")[0], tmp_path / "v")
    assert load_volume(str(tmp_path / "v.npz")).shape == (1, 4, 4, 4, 4)
    with pytest.raises(UserError, match="does not match"):
        load_volume(str(tmp_path / "v.npz"), 8)
    with pytest.raises(UserError, match="unknown built-in volume"):
        load_volume("builtin:teapot")
