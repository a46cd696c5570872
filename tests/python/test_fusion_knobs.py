"""The fusion knobs are one table (avsplat.fusion_knobs(), C++ fusion/fusion_knobs.h): the Python
keywords and their checks, the defaults, the docstrings and the command line's flags and --help
all agree with it, knob by knob."""
import math
import os
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")
KNOBS = avsplat.fusion_knobs()
NUMBERS = [k for k in KNOBS if k["kind"] == "number"]
CHOICES = [k for k in KNOBS if k["kind"] == "choice"]


def samples(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (n, 3)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32), \
        rng.normal(size=n).astype(np.float32)


def test_table_lists_every_field_once_with_the_struct_defaults():
    names = [k["name"] for k in KNOBS]
    assert names[0] == "policy" and len(names) == len(set(names))
    assert set(names) == set(avsplat.defaults["fusion"])
    for k in KNOBS:
        assert k["default"] == avsplat.defaults["fusion"][k["name"]]
        assert k["doc"] and k["range"] and k["flag"] == "--" + k["name"].replace("_", "-")
    assert {k["name"]: k["default"] for k in NUMBERS}["tau0"] == 0.7
    assert {k["name"]: k["words"] for k in CHOICES}["policy"] == ["mean", "softmax", "occupancy"]


@pytest.mark.parametrize("function", [avsplat.fuse_voxels, avsplat.fuse_gaussians])
def test_docstrings_list_every_knob_with_default_and_range(function):
    doc = function.__doc__
    for k in KNOBS[1:]:
        if k["gaussian_only"] and function is avsplat.fuse_voxels:
            continue
        default = k["default"] if k["kind"] == "choice" else format(k["default"], "g")
        assert f"{k['name']}={default}: {k['doc']}; {k['range']}" in doc, k["name"]


@pytest.mark.parametrize("knob", NUMBERS, ids=lambda k: k["name"])
def test_every_number_knob_rejects_a_value_outside_its_range(knob):
    p, f, c = samples()
    bad = {"tau_max": 0.1, "trim_mass": 1.5}.get(knob["name"], -1.0)  # tau_max < tau_min's default
    with pytest.raises(ValueError, match=f"FusionParams.{knob['name']}: .*expected {knob['range']}"):
        avsplat.fuse_voxels(p, f, 0.3, c, **{knob["name"]: bad})
    with pytest.raises(ValueError, match=knob["name"]):
        avsplat.fuse_voxels(p, f, 0.3, c, **{knob["name"]: math.nan})
    avsplat.fuse_voxels(p, f, 0.3, c, **{knob["name"]: knob["default"]})


@pytest.mark.parametrize("knob", CHOICES[1:], ids=lambda k: k["name"])
def test_every_choice_knob_takes_its_words_and_names_them_when_wrong(knob):
    p, f, c = samples()
    call = avsplat.fuse_gaussians if knob["gaussian_only"] else avsplat.fuse_voxels
    args = (avsplat.GaussianCloud(p, np.full((len(p), 3), 0.01), np.tile([1.0, 0, 0, 0], (len(p), 1)),
                                  np.full(len(p), 0.5), np.zeros((len(p), 1, 3)), confidence=c), 0.3) \
        if knob["gaussian_only"] else (p, f, 0.3, c)
    for word in knob["words"]:
        call(*args, **{knob["name"]: word})
    with pytest.raises(ValueError, match=f"{knob['name']}: 'bogus' is not one of " + ", ".join(
            f"'{w}'" for w in knob["words"])):
        call(*args, **{knob["name"]: "bogus"})
    with pytest.raises(TypeError, match=knob["name"]):
        call(*args, **{knob["name"]: 3})


def test_unknown_knob_names_the_table():
    p, f, c = samples()
    with pytest.raises(TypeError, match="unexpected keyword argument.*'tau'.*the knobs are tau0, alpha"):
        avsplat.fuse_voxels(p, f, 0.3, c, tau=1)
    with pytest.raises(TypeError, match="'shape' applies to fuse_gaussians only"):
        avsplat.fuse_voxels(p, f, 0.3, c, shape="moment")


@pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")
def test_fuse_help_lists_every_knob_flag_with_its_default():
    text = subprocess.run([BIN, "fuse", "--help"], capture_output=True, text=True, check=True).stdout
    for k in KNOBS:
        line = next((l for l in text.splitlines() if l.strip().startswith(k["flag"] + " ")), None)
        assert line is not None, k["flag"]
        default = k["default"] if k["kind"] == "choice" else format(k["default"], "g")
        assert f"[{default}]" in line or f"[{k['default']}]" in line, line
        if k["kind"] == "choice":
            assert "|".join(k["words"]) in line, line


@pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")
def test_cli_refuses_a_bad_word_listing_the_valid_ones(tmp_path):
    r = subprocess.run([BIN, "fuse", "x.ply", "-o", str(tmp_path / "o.ply"), "--voxel", "0.1", "--weights", "x"],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "'x' is not one of softmax|sparsemax" in r.stderr
