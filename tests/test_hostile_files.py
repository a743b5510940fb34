"""Hostile ``.tetc`` files: every case is rejected cleanly, fast, and within a memory budget.

Each case runs in a worker process (one for the whole module, restarted if it dies) whose address
space is limited to what it uses after warming up plus ``MEMORY_BUDGET``, under a ``TIME_LIMIT``
alarm. A case passes when the whole read API (metadata, every level's mesh and forest, the stream
of every array, simplification to a ratio) either succeeds or raises a :class:`TetcError`; a crash,
another exception type (a traceback), a MemoryError, a timeout or a dead worker fail the test.

The cases: hypothesis over bit flips, truncations, rewritten metadata values (CRC recomputed, so
they reach the decoder), section headers with crafted counts, lengths and dtypes; and the known
attacks: the forest bomb (a 90 KB file whose metadata announced 4 GB of forest), absurd counts.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import resource
import signal
import struct
import time
import traceback

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

TIME_LIMIT = 2.0  # seconds per case
MEMORY_BUDGET = 300 << 20  # bytes of address space above the warmed-up worker's


# -- the worker ---------------------------------------------------------------------------------

def _exercise(data: bytes) -> None:
    """Everything a reader of an untrusted file may call."""
    import gatun_py
    from gatun_py.codec import TetcReader
    from gatun_py.codec.info import tetc_info

    r = TetcReader(data)
    tetc_info(r)
    r.forest_merges()
    r.read_dependencies()
    for b in (r.brick(k) for k in range(r.n_bricks)):  # a one-brick file is its own brick 0
        for lv in b.levels:
            b.decode_mesh(lv["level"], jobs=2)  # the connectivity on a thread of its own
            b.read_forest(lv["level"])
        for name, _, k in b.arrays:
            for _ in b.iter_decode(0, scalar=name, component=None if k == 1 else "magnitude"):
                pass
    if r.n_bricks > 1:  # bricks skipped by their ranges, the rest decoded on threads and renumbered
        try:  # (a rewritten range is the verb's to reject, not this harness's)
            lo, hi = (float(x) for x in r.meta["scalar_range"])
        except (KeyError, TypeError, ValueError):
            lo = hi = 0.0
        gatun_py.isosurface(r, values=(lo + hi) / 2 if np.isfinite(lo + hi) else 0.0, ratio=0.5, jobs=2)
    f = gatun_py.open(data)
    f.mesh(jobs=2)
    if f.max_ratio > 0:
        f.mesh(ratio=min(0.5, f.max_ratio))


def _vm_size() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


class _Timeout(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Timeout()


def _worker(conn, warmup: list) -> None:
    from gatun_py.errors import TetcError

    for data in warmup:  # load every kernel before the address space is limited
        _exercise(data)
    limit = _vm_size() + MEMORY_BUDGET
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    signal.signal(signal.SIGALRM, _on_alarm)
    conn.send(("ready", limit, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024))
    while True:
        data = conn.recv()
        if data is None:
            return
        t0 = time.perf_counter()
        signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT)
        try:
            _exercise(data)
            outcome, message = "ok", ""
        except TetcError as e:
            outcome, message = "rejected", str(e)
        except _Timeout:
            outcome, message = "timeout", ""
        except MemoryError:
            outcome, message = "memory", traceback.format_exc()
        except Exception:  # noqa: BLE001 - any other exception is the failure we look for
            outcome, message = "traceback", traceback.format_exc()
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        conn.send((outcome, message, time.perf_counter() - t0, rss))


class Worker:
    def __init__(self, warmup):
        self.warmup = warmup
        self.stats = {"cases": 0, "rejected": 0, "ok": 0, "max_seconds": 0.0, "max_rss": 0}
        self._start()

    def _start(self):
        ctx = mp.get_context("spawn")  # a fresh interpreter: no forked numba threads
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, self.warmup), daemon=True)
        self.proc.start()
        if not self.conn.poll(600):
            raise RuntimeError("worker did not start")
        status, self.limit, self.base_rss = self.conn.recv()
        assert status == "ready"
        self.stats["base_rss"] = self.base_rss

    def run(self, data: bytes):
        self.conn.send(bytes(data))
        if not self.conn.poll(TIME_LIMIT + 10):
            self.proc.kill()
            self._start()
            return "hang", "worker did not answer", TIME_LIMIT + 10, 0
        try:
            outcome, message, seconds, rss = self.conn.recv()
        except EOFError:
            code = self.proc.exitcode
            self._start()
            return "crash", f"worker died (exit code {code})", 0.0, 0
        self.stats["cases"] += 1
        self.stats[outcome] = self.stats.get(outcome, 0) + 1
        self.stats["max_seconds"] = max(self.stats["max_seconds"], seconds)
        self.stats["max_rss"] = max(self.stats["max_rss"], rss)
        return outcome, message, seconds, rss

    def close(self):
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()


def check(worker, data, what=""):
    outcome, message, seconds, _ = worker.run(data)
    assert outcome in ("ok", "rejected"), f"{what[:300]}: {outcome} after {seconds:.2f} s\n{message}"
    assert seconds <= TIME_LIMIT, f"{what}: took {seconds:.2f} s"
    return outcome, message


# -- the files ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def files():
    """(post with forest and levels, a float64 mesh with several arrays, post in 3 bricks with
    forests and levels) as bytes."""
    from conftest import load_sample
    from gatun_py.codec import LevelPayload, encode_tetc
    from gatun_py.mesh.validate import validate_tets
    from gatun_py.simplify import build_levels, decimate
    from gatun_py.simplify.dependencies import merge_dependencies
    from gatun_py.simplify.levels import storage_forests
    from gatun_py.pipeline.bricks import compress_bricks

    mesh = load_sample("post")[0]
    forest = decimate(mesh)
    levels = build_levels(mesh, forest, 3)
    deps = merge_dependencies(mesh, forest)
    with_forest = encode_tetc([LevelPayload(x.level, x.ratio, x.n_merges, x.mesh, (f.parent, f.rank))
                               for x, f in zip(levels, storage_forests(levels))],
                              dependencies=(deps.ptr, deps.idx, deps.removed))
    rng = np.random.default_rng(5)
    n = mesh.n_points
    pd = {"p": mesh.points[:, 0].astype(np.float64) * np.pi, "rho": mesh.density.astype(np.float64),
          "id": np.arange(n, dtype=np.int32), "u": rng.normal(size=(n, 3))}
    arrays, _ = validate_tets(mesh.points.astype(np.float64) * 1.1, None, mesh.tets, scalar_name="p", point_data=pd)
    bricked = compress_bricks(mesh, 3, jobs=1, levels=2)
    return _Files(with_forest, encode_tetc([LevelPayload(0, 0.0, 0, arrays)]), bricked)


class _Files(tuple):
    """The two valid files (a short repr: hypothesis prints the arguments of a failing case)."""

    def __new__(cls, *files):
        return super().__new__(cls, files)

    def __repr__(self):
        return f"<{len(self)} valid .tetc files: {', '.join(str(len(f)) for f in self)} bytes>"


@pytest.fixture(scope="module")
def worker(files):
    w = Worker(list(files))
    yield w
    w.close()
    stats = dict(w.stats, max_rss_above_base_mb=round((w.stats["max_rss"] - w.stats["base_rss"]) / 2**20, 1))
    print(f"\nhostile files: {json.dumps(stats)}")
    out = os.environ.get("TETC_HOSTILE_STATS")  # the bench report reads the figures from here
    if out:
        with open(out, "w") as fh:
            json.dump(stats, fh)


def _split(data: bytes):
    """(metadata dict, [(name, payload)]) of a valid file."""
    from gatun_py.codec.container import split_container

    return split_container(data)


def _build(meta, sections, major=None) -> bytes:
    from gatun_py.codec.container import build_container

    data = bytearray(build_container(meta, sections))
    if major is not None:
        struct.pack_into("<H", data, 8, major)
    return bytes(data)


# -- known attacks ------------------------------------------------------------------------------

def test_valid_files_decode(worker, files):
    for data in files:
        assert check(worker, data)[0] == "ok"


def test_bad_array_copies(worker):
    """Format 8's array copies pointing at a missing array or component, at themselves, at a copy (a
    chain or a cycle), at another dtype, or in a format-7 file: rejected, whatever reads them."""
    from test_array_copies import _bad_copy_cases

    data, cases = _bad_copy_cases()
    assert check(worker, data)[0] == "ok"
    for what, bad in cases.items():
        assert check(worker, bad, what)[0] == "rejected", what


def test_dependency_bombs(worker, files):
    """The deps section lies about its counts, or is an LZMA bomb, or rebuilds bad ranks: rejected
    before anything large is allocated."""
    import lzma

    from gatun_py.codec.dependencies import _HEADER, _MAGIC

    meta, sections = _split(files[0])
    names = [n for n, _ in sections]
    assert "deps" in names
    i = names.index("deps")
    _, k, _, nnz = _HEADER.unpack_from(sections[i][1])
    body = sections[i][1][_HEADER.size:]
    bomb = lzma.compress(bytes(1 << 26), preset=9)
    raw = lzma.decompress(body)
    bad_rank = bytearray(raw)
    bad_rank[8 * k:8 * k + 4] = bytes([255] * 4)  # the first gaps (low-byte plane) reach below rank 0
    cases = {
        "nnz huge": _HEADER.pack(_MAGIC, k, 0, 2**40) + body,
        "nnz at the cap": _HEADER.pack(_MAGIC, k, 0, 4096 * k) + bomb,
        "merges wrong": _HEADER.pack(_MAGIC, k + 1, 0, nnz) + body,
        "truncated": sections[i][1][: len(sections[i][1]) // 2],
        "bad magic": b"XXXX" + sections[i][1][4:],
        "gap out of range": _HEADER.pack(_MAGIC, k, 0, nnz) + lzma.compress(bytes(bad_rank)),
    }
    for what, payload in cases.items():
        secs = list(sections)
        secs[i] = ("deps", payload)
        m = json.loads(json.dumps(meta))
        if what == "merges wrong":
            m["dependencies"]["merges"] = k + 1
        assert check(worker, _build(m, secs), what)[0] == "rejected", what
    # metadata says there are dependencies, the section is gone
    assert check(worker, _build(meta, [x for x in sections if x[0] != "deps"]), "no deps")[0] == "rejected"


def test_forest_bomb(worker, files):
    """A level claiming 2^29 - 1 vertices: rejected before the forest or anything else is allocated."""
    meta, sections = _split(files[0])
    for key in ("points",):
        for value in (2**29 - 1, 2**31 - 1, 10**6):
            m = json.loads(json.dumps(meta))
            for lv in m["levels"]:
                lv[key] = value
            m[key] = value
            assert check(worker, _build(m, sections), f"{key}={value}")[0] == "rejected"


def test_forest_bomb_with_matching_forest_header(worker, files):
    """The forest header agrees with the lie: the geometry section still rules it out."""
    import lzma

    meta, sections = _split(files[0])
    n = 1 << 27
    body = lzma.compress(bytes(8 * n // 64), preset=0)  # 2 MB of zeros, expands 8n / 64
    out = []
    for name, payload in sections:
        if name == "L0/forest":
            payload = struct.pack("<4sII", b"GFR1", n, 5) + body
        out.append((name, payload))
    m = json.loads(json.dumps(meta))
    m["levels"][0]["points"] = n
    assert check(worker, _build(m, out))[0] == "rejected"


@pytest.mark.parametrize("key,value", [("tets", 2**31 - 1), ("boundary_faces", 2**31 - 1),
                                       ("boundary_vertices", 10**9), ("referenced_points", -1),
                                       ("level", 63), ("points", 0)])
def test_absurd_level_counts(worker, files, key, value):
    meta, sections = _split(files[0])
    meta["levels"][0][key] = value
    assert check(worker, _build(meta, sections), f"{key}={value}")[0] == "rejected"


@pytest.mark.parametrize("edit", [
    {"points_dtype": "float16"}, {"points_dtype": "int32"}, {"arrays": []}, {"arrays": "x"},
    {"arrays": [{"name": "p", "dtype": "float64", "components": 70000}]},
    {"arrays": [{"name": "p", "dtype": "complex128", "components": 1}]},
    {"arrays": [{"name": "p", "dtype": "float64", "components": 1}] * 2},
    {"arrays": [{"name": "q", "dtype": "float64", "components": 1}]},
    {"scalar": "u"}, {"scalar": 5},
])
def test_crafted_array_metadata(worker, files, edit):
    meta, sections = _split(files[1])
    meta.update(edit)
    assert check(worker, _build(meta, sections), str(edit))[0] == "rejected"


def test_version_and_array_list_must_agree(worker, files):
    meta, sections = _split(files[1])
    assert check(worker, _build(meta, sections, major=1))[0] == "rejected"


def _array_sections(sections):
    return [i for i, (name, _) in enumerate(sections) if "/array/" in name or name.endswith("/points64")]


@pytest.mark.parametrize("field,value", [("n", 2**32 - 1), ("k", 0), ("k", 65535), ("code", 99),
                                         ("coder", 7), ("length", 2**32 - 1), ("length", 0), ("shift", 64),
                                         ("kind", 200)])
def test_crafted_array_section_headers(worker, files, field, value):
    meta, sections = _split(files[1])
    for i in _array_sections(sections):
        name, payload = sections[i]
        p = bytearray(payload)
        if field == "code":
            p[1] = value
        elif field == "k":
            struct.pack_into("<H", p, 2, value)
        elif field == "n":
            struct.pack_into("<I", p, 4, value)
        elif field == "length":
            struct.pack_into("<I", p, 8 + 3, value)
        else:
            p[8 + {"kind": 0, "shift": 1, "coder": 2}[field]] = value
        crafted = list(sections)
        crafted[i] = (name, bytes(p))
        assert check(worker, _build(meta, crafted), f"{name} {field}={value}")[0] == "rejected"


def test_array_section_lzma_bomb(worker, files):
    """An array section (planes coder) whose LZMA stream expands far past what its header announces."""
    import lzma

    meta, sections = _split(files[1])
    i = _array_sections(sections)[0]
    name, payload = sections[i]
    bomb = bytes([8]) + lzma.compress(bytes(200 << 20), preset=1)
    head = bytearray(payload[:8])
    struct.pack_into("<H", head, 2, 1)  # one component: the bomb
    head += struct.pack("<BBBI", 0, 0, 1, len(bomb))
    crafted = list(sections)
    crafted[i] = (name, bytes(head) + bomb)
    assert check(worker, _build(meta, crafted))[0] == "rejected"


# -- hypothesis ---------------------------------------------------------------------------------

HYPO = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))


@HYPO
@given(st.data())
def test_bit_flips_and_truncations(worker, files, data):
    blob = bytearray(files[data.draw(st.integers(0, len(files) - 1))])
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(blob) - 1))
        blob[pos] ^= 1 << data.draw(st.integers(0, 7))
    if data.draw(st.booleans()):
        blob = blob[: data.draw(st.integers(0, len(blob)))]
    check(worker, bytes(blob))


_VALUES = st.one_of(st.integers(-2**63, 2**64), st.sampled_from([0, -1, 1, 2**31 - 1, 2**32, 2**29 - 1]),
                    st.floats(allow_nan=True), st.text(max_size=8), st.none(), st.booleans(),
                    st.lists(st.integers(-3, 3), max_size=3))


@HYPO
@given(st.data())
def test_rewritten_metadata(worker, files, data):
    """Any value of any metadata key (top level, a level, an array entry) with a valid CRC."""
    meta, sections = _split(files[data.draw(st.integers(0, len(files) - 1))])
    where = data.draw(st.sampled_from(["top", "level", "array", "brick"]))
    target = meta
    bricks = meta.get("bricks") or [meta]  # a bricked file keeps its levels per brick
    if where == "level":
        target = data.draw(st.sampled_from(data.draw(st.sampled_from(bricks))["levels"]))
    elif where == "brick":
        target = data.draw(st.sampled_from(bricks))
    elif where == "array" and "arrays" in meta:
        target = data.draw(st.sampled_from(meta["arrays"]))
    key = data.draw(st.sampled_from(sorted(target)))
    target[key] = data.draw(_VALUES)
    check(worker, _build(meta, sections), f"{where}.{key}={target[key]!r}")


@pytest.mark.parametrize("value", ["", [1.0], "12", [0.0, 1.0, 2.0], None])
def test_scalar_range_not_a_pair(worker, files, value):
    """A scalar range of any length but two (found by the test above: an empty one once reached
    the bricked isosurface's brick choice as an empty tuple)."""
    for data in files:
        meta, sections = _split(data)
        meta["scalar_range"] = value
        check(worker, _build(meta, sections), f"top.scalar_range={value!r}")


@HYPO
@given(st.data())
def test_rewritten_section_bytes(worker, files, data):
    """Section payloads changed behind a valid CRC: header fields, truncation, random bytes."""
    meta, sections = _split(files[data.draw(st.integers(0, len(files) - 1))])
    i = data.draw(st.integers(0, len(sections) - 1))
    name, payload = sections[i]
    p = bytearray(payload)
    action = data.draw(st.sampled_from(["u32", "byte", "cut", "append"]))
    if action == "u32" and len(p) >= 4:
        pos = data.draw(st.integers(0, min(len(p), 64) - 4))
        struct.pack_into("<I", p, pos, data.draw(st.sampled_from([0, 1, 2**31 - 1, 2**32 - 1, 2**29, 12345])))
    elif action == "byte" and p:
        p[data.draw(st.integers(0, len(p) - 1))] = data.draw(st.integers(0, 255))
    elif action == "cut":
        p = p[: data.draw(st.integers(0, len(p)))]
    else:
        p += bytes(data.draw(st.integers(1, 64)))
    sections[i] = (name, bytes(p))
    check(worker, _build(meta, sections), f"{name} {action}")


@HYPO
@given(st.data())
def test_rewritten_tet_streams(worker, files, data):
    """A level's tet stream changed behind a valid CRC, in a file that says format 5 (coding 2) or
    format 4 (the coding-1 decoder then reads coding-2 data): a clean error or a consistent mesh."""
    meta, sections = _split(files[data.draw(st.integers(0, len(files) - 1))])
    tets = [i for i, (name, _) in enumerate(sections) if name.endswith("/tets")]
    i = data.draw(st.sampled_from(tets))
    p = bytearray(sections[i][1])
    for _ in range(data.draw(st.integers(0, 3))):
        if p:
            p[data.draw(st.integers(0, len(p) - 1))] ^= 1 << data.draw(st.integers(0, 7))
    if data.draw(st.booleans()):
        p = p[: data.draw(st.integers(0, len(p)))]
    sections[i] = (sections[i][0], bytes(p))
    major = data.draw(st.sampled_from([None, 4]))
    check(worker, _build(meta, sections, major=major), f"{sections[i][0]} format {major}")


def test_crc_is_what_catches_plain_damage(files):
    """Sanity of the harness: a flipped payload byte without a new CRC is a CRC error."""
    from gatun_py.codec import TetcReader
    from gatun_py.errors import CorruptFileError

    data = bytearray(files[1])
    data[-10] ^= 0xFF
    with pytest.raises(CorruptFileError):
        TetcReader(bytes(data)).decode_mesh(0)


def test_geometry_header_and_metadata_agree_on_a_huge_count(worker, files):
    """Metadata and geometry header both claim the most vertices the geometry section could hold."""
    from gatun_py.codec import geometry

    meta, sections = _split(files[0])
    out = []
    for name, payload in sections:
        if name == "L0/geometry":
            lengths = struct.unpack_from("<4I", payload, 6)
            n = geometry.max_vertices(lengths)
            p = bytearray(payload)
            struct.pack_into("<I", p, 2, n)
            payload = bytes(p)
        out.append((name, payload))
    for key in ("points", "referenced_points"):
        meta["levels"][0][key] = n
    meta["points"] = n
    assert check(worker, _build(meta, out), f"n={n}")[0] == "rejected"


# -- format 8: value tables chained across levels -------------------------------------------------

_CHAINED_AT, _TABLE_LENGTHS_AT, _STEPS_AT = 22, 23, 39  # the coding-4 and -5 geometry headers' fields


def _header_size(block) -> int:
    return 40 if block[0] == 5 else 39


def _chained_blocks(sections) -> list:
    """Indices of the coding-4 and -5 geometry sections that chain a table to the next level's."""
    return [i for i, (name, p) in enumerate(sections)
            if name.endswith("/geometry") and p[0] in (4, 5) and p[_CHAINED_AT] != 0]


def test_the_files_chain_their_tables(files):
    """The levelled and the bricked file chain tables (else the cases below test nothing)."""
    for data in (files[0], files[2]):
        assert _chained_blocks(_split(data)[1])


def test_chain_to_a_level_the_file_does_not_hold(worker, files):
    """The coarsest level dropped (metadata and sections): the level before it chains to nothing."""
    meta, sections = _split(files[0])
    last = meta["levels"][-1]["level"]
    meta["levels"] = meta["levels"][:-1]
    kept = [(name, p) for name, p in sections if not name.startswith(f"L{last}/") and name != "deps"]
    meta.pop("dependencies", None)
    assert any(name == f"L{last - 1}/geometry" for name, _ in kept)
    outcome, message = check(worker, _build(meta, kept), "coarsest level dropped")
    assert outcome == "rejected" and "coarser level" in message, message


def test_levels_in_another_order(worker, files):
    """The level list reversed: every chain then points at a finer level's tables, or off the file."""
    meta, sections = _split(files[0])
    meta["levels"] = meta["levels"][::-1]
    check(worker, _build(meta, sections), "levels reversed")


@pytest.mark.parametrize("chained", range(16))
def test_rewritten_chain_bits(worker, files, chained):
    """Every chain byte on every level's geometry (a chain on a channel without a table, to a level
    without that table, or none where the tables need one)."""
    for data in (files[0], files[2]):
        meta, sections = _split(data)
        out = []
        for name, p in sections:
            if name.endswith("/geometry") and p[0] in (4, 5):
                p = bytearray(p)
                p[_CHAINED_AT] = chained
                p = bytes(p)
            out.append((name, p))
        check(worker, _build(meta, out), f"chained={chained}")


@HYPO
@given(st.data())
def test_damaged_coarser_tables(worker, files, data):
    """A coarser level's table stream (what a finer level's decode reads of it) damaged behind a
    valid CRC: flipped bits, or its length field rewritten."""
    meta, sections = _split(files[data.draw(st.sampled_from([0, 2]))])
    geo = [i for i, (name, p) in enumerate(sections)
           if name.endswith("/geometry") and p[0] in (4, 5) and any(struct.unpack_from("<4I", p, _TABLE_LENGTHS_AT))]
    i = data.draw(st.sampled_from(geo))
    name, p = sections[i]
    p = bytearray(p)
    lengths = struct.unpack_from("<4I", p, _TABLE_LENGTHS_AT)
    ch = data.draw(st.sampled_from([c for c in range(4) if lengths[c]]))
    if data.draw(st.booleans()):
        start = _header_size(p) + sum(lengths[:ch])
        for _ in range(data.draw(st.integers(1, 3))):
            p[start + data.draw(st.integers(0, lengths[ch] - 1))] ^= 1 << data.draw(st.integers(0, 7))
    else:
        struct.pack_into("<I", p, _TABLE_LENGTHS_AT + 4 * ch,
                         data.draw(st.sampled_from([0, 1, lengths[ch] - 1, lengths[ch] + 1, 2**32 - 1])))
    sections[i] = (name, bytes(p))
    check(worker, _build(meta, sections), f"{name} tables")


# -- format 9: rank steps ------------------------------------------------------------------------------


def _step_blocks(sections) -> list:
    """Indices of the coding-5 geometry sections with a channel coded in rank steps."""
    return [i for i, (name, p) in enumerate(sections)
            if name.endswith("/geometry") and p[0] == 5 and p[_STEPS_AT] != 0]


def test_the_files_take_rank_steps(files):
    """The levelled and the bricked file have step channels (post's z), else the cases below test
    nothing."""
    for data in (files[0], files[2]):
        assert _step_blocks(_split(data)[1])


@pytest.mark.parametrize("steps", list(range(16)) + [0x10, 0xFF])
def test_rewritten_step_bits(worker, files, steps):
    """Every step byte on every level's geometry: steps on a channel without a table are refused,
    on a table channel that was coded without them (or the reverse) the decode fails or differs,
    never crashes."""
    for data in (files[0], files[2]):
        meta, sections = _split(data)
        out = []
        for name, p in sections:
            if name.endswith("/geometry") and p[0] == 5:
                p = bytearray(p)
                p[_STEPS_AT] = steps
                p = bytes(p)
            out.append((name, p))
        outcome, message = check(worker, _build(meta, out), f"steps={steps}")
        if steps >= 0x10:
            assert outcome == "rejected" and "rank steps" in message, message


@HYPO
@given(st.data())
def test_damaged_step_streams(worker, files, data):
    """A step channel's stream damaged behind a valid CRC: flipped bits, or cut short."""
    meta, sections = _split(files[data.draw(st.sampled_from([0, 2]))])
    i = data.draw(st.sampled_from(_step_blocks(sections)))
    name, p = sections[i]
    p = bytearray(p)
    lengths = struct.unpack_from("<4I", p, 6)
    ch = data.draw(st.sampled_from([c for c in range(4) if p[_STEPS_AT] >> c & 1]))
    tables = sum(struct.unpack_from("<4I", p, _TABLE_LENGTHS_AT))
    start = _header_size(p) + tables + sum(lengths[:ch])
    if data.draw(st.booleans()):
        for _ in range(data.draw(st.integers(1, 3))):
            p[start + data.draw(st.integers(0, lengths[ch] - 1))] ^= 1 << data.draw(st.integers(0, 7))
    else:
        cut = data.draw(st.integers(1, lengths[ch]))
        struct.pack_into("<I", p, 6 + 4 * ch, lengths[ch] - cut)
        del p[start + lengths[ch] - cut:start + lengths[ch]]
    sections[i] = (name, bytes(p))
    check(worker, _build(meta, sections), f"{name} step stream")
