from edge_runtime.core.memo import Recent


def test_recent_keeps_the_last_values_and_drops_the_oldest():
    m = Recent(2)
    assert m.get("a") is None
    assert m.put("a", 1) == 1 and m.put("b", 2) == 2
    m.put("a", 3)                      # a key already there: replaced, nothing dropped
    assert (m.get("a"), m.get("b"), len(m)) == (3, 2, 2)
    m.put("c", 4)                      # full: the oldest put ("a") goes
    assert (m.get("a"), m.get("b"), m.get("c")) == (None, 2, 4)
    m.clear()
    assert len(m) == 0 and m.get("b") is None
