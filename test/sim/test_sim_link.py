"""The faulty link's statistics and order against their definitions (pure, no ROS)."""

from cbha_inverse.sim.link import FaultyLink, LinkFaults
import numpy as np
import pytest


def run(faults, n, period=0.01, seed=0):
    """Send ``0..n-1`` every ``period`` s, receiving on a 1 ms grid; return (id, sent, got)."""
    link = FaultyLink(faults, seed)
    out = []
    for i in range(n):
        link.send(i, i * period)
        for t in np.arange(i * period, (i + 1) * period, 0.001):
            out.extend((m, t) for m in link.receive(t))
    out.extend((m, np.inf) for m in link.receive(np.inf))
    ids = np.array([m for m, _ in out])
    return link, ids, ids * period, np.array([t for _, t in out])


def test_a_clean_link_delays_every_message_in_order():
    link, ids, sent, got = run(LinkFaults(delay=0.005), 100)
    np.testing.assert_array_equal(ids, np.arange(100))
    np.testing.assert_allclose(got - sent, 0.005, atol=1.001e-3)     # the 1 ms receive grid
    assert link.counts == {'sent': 100, 'dropped': 0, 'duplicated': 0, 'reordered': 0,
                           'delivered': 100}


def binomial_band(p, n):
    """Return the 5-sigma band of a binomial count."""
    sigma = np.sqrt(n * p * (1 - p))
    return n * p - 5 * sigma, n * p + 5 * sigma


def test_drop_and_duplicate_rates():
    n = 4000
    link, ids, _, _ = run(LinkFaults(drop=0.05, duplicate=0.1), n)
    low, high = binomial_band(0.05, n)
    assert low < link.counts['dropped'] < high
    assert low < n - np.unique(ids).size < high
    kept = n - link.counts['dropped']
    low, high = binomial_band(0.1, kept)
    assert low < ids.size - np.unique(ids).size < high
    assert link.counts['duplicated'] == ids.size - np.unique(ids).size
    assert np.all(np.diff(ids) >= 0)                 # a duplicate comes right after its original


def test_jitter_stays_in_its_band_and_keeps_the_order():
    delay, jitter = 0.010, 0.005
    _, ids, sent, got = run(LinkFaults(delay=delay, jitter=jitter), 2000, period=0.05)
    latency = got - sent
    assert latency.min() >= delay - jitter - 1e-9 and latency.max() <= delay + jitter + 1.001e-3
    assert abs(latency.mean() - delay - 0.0005) < 0.0005   # uniform: the mean is the delay
    assert latency.std() > 0.8 * jitter / np.sqrt(3)       # ... and it does spread
    # at a period shorter than the jitter the order still holds
    _, ids, _, _ = run(LinkFaults(delay=delay, jitter=jitter), 2000, period=0.002)
    np.testing.assert_array_equal(ids, np.arange(2000))


def test_a_reordered_message_is_overtaken_by_the_next():
    n = 2000
    link, ids, _, _ = run(LinkFaults(delay=0.01, reorder=0.05, reorder_delay=0.025), n)
    assert sorted(ids) == list(range(n))
    overtaken = {i for k, i in enumerate(ids) if k and i < ids[:k].max()}
    low, high = binomial_band(0.05, n)
    assert low < link.counts['reordered'] < high
    assert len(overtaken) == link.counts['reordered']


def test_the_seed_makes_a_run_repeatable():
    faults = LinkFaults(drop=0.1, delay=0.01, jitter=0.005, duplicate=0.1, reorder=0.1)
    a, b, c = (run(faults, 300, seed=s)[1:] for s in (1, 1, 2))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize('bad', [{'drop': 1.5}, {'duplicate': -0.1}, {'delay': -1.0},
                                 {'jitter': float('nan')}])
def test_bad_faults_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        LinkFaults(**bad)
