"""Issue #47 item 5: what a newcomer tripped on (tried as a new user would, 2026-12-07), each
reproduced as met."""


import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rodphase import store as S
from rodphase.cli import main


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_error(out, *words) -> str:
    """Exit 2, stderr exactly one 'error:' line naming every word."""
    assert out.exit_code == 2, (out.output, out.exception)
    lines = out.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), out.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


# ---------------------------------------------------------------- --force on a file not a store

@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("what", ["yaml", "foreign hdf5"])
def test_force_never_replaces_a_file_that_is_not_a_store(tmp_path, force, what):
    """`-o typo.yaml` was refused with advice to use --force; following it replaced the
    YAML with an HDF5 store."""
    target = tmp_path / ("typo.yaml" if what == "yaml" else "other.h5")
    if what == "yaml":
        target.write_text("scene: twist_under_load\nrod: {elements: 20}\n")
    else:
        with h5py.File(target, "w") as f:
            f["data"] = np.arange(3)
    before = target.read_bytes()
    out = cli("run", "twist_under_load", "-o", target, *(["--force"] if force else []))
    line = one_error(out, str(target), "--force replaces only a rodphase store",
                     "nothing was changed")
    assert "or --force to replace it" not in line
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_force_still_replaces_a_store_of_another_config_or_an_empty_file(tmp_path):
    target = tmp_path / "old.h5"
    with S.open_store(target, config_text="a: 1\n", config_hash="other", version="0",
                      kind="run"):
        pass
    with pytest.raises(S.StoreMismatch, match="or --force to replace it"):
        S.open_store(target, config_text="b: 1\n", config_hash="mine", version="0", kind="run")
    with S.open_store(target, config_text="b: 1\n", config_hash="mine", version="0", kind="run",
                      replace=True):
        pass
    empty = tmp_path / "empty.h5"
    empty.touch()
    with S.open_store(empty, config_text="b: 1\n", config_hash="mine", version="0", kind="run",
                      replace=True):
        pass
    with S.read_store(empty) as store:
        assert store.attrs["config_hash"] == "mine"
