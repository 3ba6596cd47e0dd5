"""A memory's start-up tables from one chunked FK pass (models/networks/member_tables.py, issue 40's
30-minute library): the same values as each table's own function, at a bounded peak memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from models.networks import dance_stream as ds
from models.networks import member_tables as mt
from models.networks.feet import member_contacts


@pytest.fixture(scope="module")
def memory():
    """The shipped default's exemplars (K, M, 2 seg, P) as a stream reads them, its counts and seg."""
    from models.generate import load_model

    model = load_model(None).model
    return ds._cached_members(model), model.member_count.numpy(), model.config.seg


def test_member_tables_are_each_tables_own_values(memory):
    """Chunked (a few codes at a time, so several chunks and a short last one), every table is
    bit for bit what member_dips, code_energy, code_frequency and member_contacts give."""
    members, counts, seg = memory
    t = mt.member_tables(members, counts, seg, chunk_frames=7 * members.shape[1] * members.shape[2])
    np.testing.assert_array_equal(t.dips, mt.member_dips(members[:, :, : seg + 2], seg))
    speed = mt.member_speed(members[:, :, :seg]).mean(-1)
    np.testing.assert_array_equal(t.speed, speed)
    np.testing.assert_array_equal(t.energy, mt.code_energy(members, counts, seg))
    np.testing.assert_array_equal(t.frequency, mt.code_frequency(members, counts))
    contacts, floor = member_contacts(mt.member_positions(members), counts)
    np.testing.assert_array_equal(t.contacts, contacts)
    assert t.floor == floor


def test_member_tables_peak_memory_is_bounded_by_chunks(memory):
    """A 16-member memory (the default's exemplars tiled: 131,072 exemplar frames, 94 MB of float64
    FK points at once) builds its tables under 60 MB of traced NumPy peak; four FK passes of the
    whole memory, as the stream's start-up made them, took several times that."""
    members, counts, seg = memory
    reps = -(-16 // members.shape[1])
    big = np.ascontiguousarray(np.tile(members, (1, reps, 1, 1))[:, :16])
    full = np.full_like(counts, 16)
    tracemalloc.start()
    try:
        mt.member_tables(big, full, seg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 60e6, f"member_tables peaked at {peak / 1e6:.0f} MB traced"
