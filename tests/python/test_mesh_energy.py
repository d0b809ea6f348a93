"""trbc.Mesh (arrays, files, meshio round trip) and trbc.membrane_energy against `trbc forces`."""
import numpy as np
import pytest

import trbc


def perturbed_icosphere(level=2, amplitude=0.05, seed=3):
    m = trbc.Mesh.icosphere(level)
    rng = np.random.default_rng(seed)
    m.vertices = m.vertices * (1.0 + amplitude * rng.uniform(-1, 1, size=(m.n_vertices, 1)))
    return m


def test_icosphere_arrays_and_geometry_match_mesh_info(tmp_path, run_cli):
    m = trbc.Mesh.icosphere(3)
    assert m.vertices.shape == (642, 3) and m.faces.shape == (1280, 3)
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int32
    v = m.vertices
    v[0, 0] += 0.0  # a view: writes reach the mesh without a copy
    assert np.shares_memory(v, m.vertices)
    m.write(str(tmp_path / "s.off"))
    info = run_cli("mesh", "info", tmp_path / "s.off")
    assert m.area == pytest.approx(info["area"], rel=1e-14)
    assert m.volume == pytest.approx(info["volume"], rel=1e-14)
    assert m.reduced_volume == pytest.approx(info["reduced_volume"], rel=1e-14)
    assert 0.99 < m.reduced_volume < 1.0
    assert m.vertex_areas().sum() == pytest.approx(m.area, rel=1e-12)


@pytest.mark.parametrize("ext", ["off", "ply", "vtk"])
def test_write_read_round_trip(tmp_path, ext):
    m = perturbed_icosphere()
    path = str(tmp_path / f"m.{ext}")
    m.write(path, fields=None if ext == "off" else {"h": np.arange(m.n_vertices, dtype=float), "f": m.vertices * 2})
    r = trbc.Mesh.read(path)
    np.testing.assert_array_equal(r.faces, m.faces)
    np.testing.assert_allclose(r.vertices, m.vertices, rtol=0, atol=1e-15)


def test_meshio_round_trip(tmp_path):
    meshio = pytest.importorskip("meshio")
    m = perturbed_icosphere()
    # trbc writes, meshio reads (meshio 7 reads no legacy-VTK POLYDATA, so OFF and PLY here)
    for ext in ("off", "ply"):
        m.write(str(tmp_path / f"t.{ext}"))
        mm = meshio.read(str(tmp_path / f"t.{ext}"))
        np.testing.assert_allclose(mm.points, m.vertices, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(mm.cells_dict["triangle"], m.faces)
    # meshio writes (ASCII), trbc reads
    mm = meshio.Mesh(m.vertices, [("triangle", m.faces)])
    for name, kwargs in [("a.off", {}), ("a.ply", {"binary": False}), ("a.vtk", {"binary": False}),
                         ("a42.vtk", {"binary": False, "fmt_version": "4.2"})]:
        try:
            meshio.write(str(tmp_path / name), mm, **kwargs)
        except TypeError:  # a meshio without fmt_version
            continue
        r = trbc.Mesh.read(str(tmp_path / name))
        np.testing.assert_allclose(r.vertices, m.vertices, rtol=1e-15, atol=1e-15)
        np.testing.assert_array_equal(r.faces, m.faces)
        assert r.volume == pytest.approx(m.volume, rel=1e-14)


def test_mesh_bad_input_raises_value_error_naming_it(tmp_path):
    with pytest.raises(ValueError, match="vertices"):
        trbc.Mesh(np.zeros((4, 2)), np.zeros((1, 3), dtype=np.int32))
    with pytest.raises(ValueError, match="faces"):
        trbc.Mesh(np.zeros((3, 3)), np.array([[0, 1, 7]]))
    with pytest.raises(ValueError, match="level"):
        trbc.Mesh.icosphere(-1)
    (tmp_path / "bad.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(ValueError, match="bad.off"):
        trbc.Mesh.read(str(tmp_path / "bad.off"))
    with pytest.raises(ValueError, match="extension"):
        trbc.Mesh.read(str(tmp_path / "bad.stl"))


def test_membrane_energy_matches_trbc_forces(tmp_path, run_cli):
    ref = trbc.Mesh.icosphere(2)
    m = perturbed_icosphere()
    m.write(str(tmp_path / "m.off"))
    ref.write(str(tmp_path / "r.off"))
    moduli = dict(kb=0.7, C0=0.3, kad=0.2, DA0=0.1, ka=2.0, a3=-2, a4=8, mu=1.5, b1=0.7, b2=0.75, kA=10.0, A0=12.0,
                  kV=5.0, V0=4.0)
    e = trbc.membrane_energy(m, ref, **moduli)
    out = run_cli("forces", "--mesh", tmp_path / "m.off", "--reference", tmp_path / "r.off", "--out", tmp_path / "f.csv",
                  *[a for k, v in moduli.items() for a in (f"--{k}", v)])
    assert e["energy"] == pytest.approx(out["energy"], rel=1e-14)
    assert set(e["terms"]) == set(out["terms"]) == {"bending", "ade", "lim", "area", "volume"}
    for k, v in out["terms"].items():
        assert e["terms"][k] == pytest.approx(v, rel=1e-13)
    forces = np.loadtxt(tmp_path / "f.csv", delimiter=",", skiprows=2)  # the provenance line and the header
    assert e["forces"].shape == (m.n_vertices, 3)
    np.testing.assert_allclose(e["forces"], forces, rtol=1e-12, atol=1e-14 * np.abs(forces).max())


def test_membrane_energy_bad_moduli_raise_value_error_naming_them():
    m = trbc.Mesh.icosphere(1)
    with pytest.raises(ValueError, match="kb = -1"):
        trbc.membrane_energy(m, kb=-1.0)
    with pytest.raises(ValueError, match="A0"):
        trbc.membrane_energy(m, kb=1.0, kA=1.0)
    with pytest.raises(ValueError, match="reference"):
        trbc.membrane_energy(m, mu=1.0)
