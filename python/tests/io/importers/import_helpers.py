"""Helpers for the importer tests (imported by name: the test folder is on sys.path)."""

import warnings

import numpy as np

from scattertrack.io import InputWarning, read_reads, write_reads


def run_quietly(call):
    """``(result, [InputWarning, ...])`` of ``call()``, every warning recorded."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call()
    return result, [w.message for w in caught if issubclass(w.category, InputWarning)]


def assert_round_trip(reads, scene, path):
    """Import -> write_reads -> read_reads gives the same rows (every column, to the written precision)."""
    write_reads(path, reads)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        again = read_reads(path, scene)
    assert len(again) == len(reads)
    assert again.epc.tolist() == reads.epc.tolist()
    assert again.antenna.tolist() == reads.antenna.tolist()
    np.testing.assert_allclose(again.time_s, reads.time_s, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(again.frequency_hz, reads.frequency_hz)
    np.testing.assert_allclose(again.phase_rad, reads.phase_rad, atol=1e-6, rtol=0)
    np.testing.assert_allclose(again.rssi_dbm, reads.rssi_dbm, atol=0.005, rtol=0, equal_nan=True)
    np.testing.assert_allclose(again.doppler_hz, reads.doppler_hz, atol=0.005, rtol=0, equal_nan=True)
    if reads.channel_index is None or (reads.channel_index == -1).all():
        assert again.channel_index is None
    else:
        assert again.channel_index.tolist() == reads.channel_index.tolist()
    assert again.skipped.total == 0 and again.reordered == 0
