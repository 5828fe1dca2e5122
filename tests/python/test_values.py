"""vox.sample, vox.read and vox.slice against the tracer's first hits (an
independent reading of the same store), against each other, and their
refusals."""
import pytest

from conftest import run, tool

np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")


def test_read_rows_start_where_the_first_hits_are(store):
    """A ray along +x through voxel centres (vox index space: ijk + 0.5)
    first hits the first occupied element of that row of vox.read."""
    lo, hi = (-34, -20, -20), (34, 20, 20)
    occ = vox.read(store, (lo, hi), attr="occupancy")
    assert occ.shape == (68, 40, 40) and occ.dtype == np.float32
    assert set(np.unique(occ)) == {0.0, 1.0}
    ys, zs = np.meshgrid(np.arange(-20, 20), np.arange(-20, 20), indexing="ij")
    rays = np.stack([np.full(ys.size, -40.0), ys.ravel() + 0.5, zs.ravel() + 0.5,
                     np.ones(ys.size), np.zeros(ys.size), np.zeros(ys.size)], axis=1)
    voxels, _, hit = vox.probe(store, rays)
    assert hit.sum() > 1000
    for r in range(len(rays)):
        row = occ[:, int(ys.ravel()[r]) + 20, int(zs.ravel()[r]) + 20]
        if hit[r]:
            first = int(np.argmax(row > 0)) + lo[0]
            assert first == voxels[r, 0] and row.max() == 1.0
        else:
            assert row.max() == 0.0


def test_sample_slice_and_read_agree(store):
    info = vox.Store(store).info
    box = vox.read(store, ((-10, -10, -30), (10, 10, 30)), attr="normal")
    assert box.shape == (20, 20, 60, 3)
    plane = vox.slice(store, "y", 3, attr="normal")
    (x0, _, z0), (x1, _, z1) = info["bbox_min"], info["bbox_max"]
    assert plane.shape == (x1 - x0 + 1, z1 - z0 + 1, 3)
    assert np.array_equal(plane, vox.read(store, ((x0, 3, z0), (x1 + 1, 4, z1 + 1)), attr="normal")[:, 0])
    assert np.abs(plane).sum(axis=2).astype(bool).sum() > 50
    # Nearest samples at voxel centres are the box's elements.
    ijk = np.argwhere(np.ones((20, 20, 60), bool)) + np.array([-10, -10, -30])
    s = vox.sample(store, ijk + 0.5)
    assert s["inside"].all()
    assert np.array_equal(s["normal"].reshape(20, 20, 60, 3), box)
    assert np.array_equal(s["occupancy"].reshape(20, 20, 60) > 0, np.abs(box).sum(axis=3) > 0)
    # World points: the index-to-world map of the same points (centres at integers there).
    m = np.array(info["index_to_world"])  # rows of the matrix acting on (i, j, k, 1)
    w = np.c_[ijk.astype(float), np.ones(len(ijk))] @ m.T
    sw = vox.sample(store, w[:, :3], space="world")
    assert np.array_equal(sw["occupancy"], s["occupancy"])


def test_trilinear_between_two_voxels(store):
    """Halfway between two voxel centres along x, the trilinear occupancy is
    the mean of theirs."""
    occ = vox.read(store, ((-33, 0, 0), (33, 1, 1)), attr="occupancy")[:, 0, 0]
    pts = np.array([[x + 1.0, 0.5, 0.5] for x in range(-33, 32)])
    s = vox.sample(store, pts, mode="trilinear")
    inside = s["inside"]
    want = (occ[:-1] + occ[1:]) / 2
    assert np.allclose(s["occupancy"][inside], want[inside])
    assert np.isnan(s["occupancy"][~inside]).all()


def test_refusals_name_the_problem(store):
    with pytest.raises(RuntimeError, match=r"region is 2048 x 2048 x 2048 float32, 32 GiB, above max_bytes"):
        vox.read(store, ((0, 0, 0), (2048, 2048, 2048)))
    with pytest.raises(ValueError, match="attribute 'density': this store keeps occupancy, normal"):
        vox.read(store, ((0, 0, 0), (1, 1, 1)), attr="density")
    with pytest.raises(ValueError, match="points must be an"):
        vox.sample(store, [1, 2, 3])
    with pytest.raises(ValueError, match="mode must be"):
        vox.sample(store, [[1, 2, 3]], mode="cubic")
    with pytest.raises(OSError, match="does not exist"):
        vox.read(store + ".missing", ((0, 0, 0), (1, 1, 1)))


def test_probe_at_prints_the_samples(store):
    code, out, err = run([tool("probe"), store, "--at", "0.5", "0.5", "-29.5", "--at", "0.5", "0.5", "0.5"])
    assert code == 0, err
    s = vox.sample(store, [[0.5, 0.5, -29.5], [0.5, 0.5, 0.5]])
    lines = out.splitlines()
    assert len(lines) == 2
    for i, line in enumerate(lines):
        words = line.split()
        assert words[3] == "inside" and float(words[5]) == s["occupancy"][i]
        assert [float(v) for v in words[7:10]] == pytest.approx(s["normal"][i].tolist(), abs=1e-7)


@pytest.fixture(scope="session")
def shell_512(workdir):
    """vox-gen's sphere at 512: a shell of index radius 240 (15/32 of the
    grid), its centre on index 0, with its level-of-detail pyramid."""
    path = workdir / "shell512.store"
    code, _, err = run([tool("gen"), "sphere", path, "--size", "512", "--quiet"])
    assert code == 0, err
    return str(path)


def test_picking_layers_are_exact_by_default(shell_512):
    """With the default level of detail (colour from the pyramid), the voxel
    layer names base voxels of the shell: radii within [239, 240], as the
    exact frame's; a coarse cell would put them several voxels off."""
    default = vox.render(shell_512, size=(200, 150), layers="voxel,position")
    assert default["stats"]["lod"]["default"] and len(default["stats"]["lod"]["stops_by_level"]) > 1
    exact = vox.render(shell_512, size=(200, 150), layers="voxel,position", lod=0)
    v = default["voxel"]
    hit = ~np.isnan(v[..., 0])
    assert hit.sum() > 4000
    radius = np.linalg.norm(v[hit], axis=1)
    assert radius.min() >= 239.0 and radius.max() <= 240.0
    # Every voxel the exact frame picks, the default frame picks too.
    assert not (~hit & ~np.isnan(exact["voxel"][..., 0])).any()


def test_ingest_array_reads_back_as_the_array(workdir):
    """vox.ingest_array then vox.read: the elements above the threshold, 0 elsewhere."""
    rng = np.random.default_rng(5)
    a = rng.random((24, 20, 16)).astype(np.float32)
    path = str(workdir / "array.store")
    vox.ingest_array(a, path, voxel_size=0.5, origin=(-4, 2, 0), threshold=0.6, quiet=True)
    back = vox.read(path, ((-4, 2, 0), (20, 22, 16)))
    assert np.array_equal(back, np.where(a > 0.6, a, 0))


def test_read_chunks_streams_a_region_above_max_bytes(store):
    """A region refused whole (above max_bytes) streams in boxes, which put
    together are vox.read of the region."""
    box = ((-33, -20, -7), (31, 25, 9))
    whole = vox.read(store, box, attr="normal")
    with pytest.raises(RuntimeError, match="max_bytes"):
        vox.read(store, box, attr="normal", max_bytes=100000)
    got = np.full(whole.shape, np.nan, np.float32)
    sizes = []
    for lo, a in vox.read_chunks(store, box, chunk=(16, 20, 6), attr="normal", max_bytes=100000):
        o = [lo[i] - box[0][i] for i in range(3)]
        got[o[0]:o[0] + a.shape[0], o[1]:o[1] + a.shape[1], o[2]:o[2] + a.shape[2]] = a
        sizes.append(a.nbytes)
    assert np.array_equal(got, whole)
    assert len(sizes) == 4 * 3 * 3 and max(sizes) == 16 * 20 * 6 * 3 * 4
