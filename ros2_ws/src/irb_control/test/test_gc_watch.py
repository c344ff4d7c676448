"""GcWatch (pdplus's gc_report_ms): every collection longer than the limit is reported with its
generation and thread, none shorter; close() removes the callback."""
import gc

from irb_control.node_util import GcWatch


def test_long_collections_are_reported_and_short_ones_not():
    lines = []
    garbage = []
    for _ in range(20000):                  # cycles for the collector to walk
        a, b = [], []
        a.append(b)
        b.append(a)
        garbage.append(a)
    watch = GcWatch(0.0, lines.append)      # every collection is "long"
    try:
        del garbage
        gc.collect(2)
        assert watch.count >= 1 and watch.worst_s > 0.0
        assert any('generation-2 collection took' in x and 'MainThread' in x for x in lines)
        quiet = GcWatch(3600.0, lines.append)   # nothing takes an hour
        n = len(lines)
        gc.collect(2)
        quiet.close()
        assert quiet.count == 0 and quiet.worst_s > 0.0
        assert len(lines) == n + 1          # only the first watch spoke
    finally:
        watch.close()
    n = len(lines)
    gc.collect(2)
    assert len(lines) == n and watch._cb not in gc.callbacks
