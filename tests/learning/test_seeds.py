import numpy as np

from g2p.learning.seeds import seed_streams


def test_each_stream_is_the_seed_sequence_child_of_its_index() -> None:
    """Known answer: the streams are SeedSequence(seed).spawn(n)[k], whatever n, so old runs reproduce."""
    for seed in (0, 3, 12345):
        streams = seed_streams(seed)
        for k, name in enumerate(("babbling", "inverse_map", "search", "tracking")):
            expected = np.random.default_rng(np.random.SeedSequence(seed).spawn(k + 1)[k]).random(5)
            np.testing.assert_array_equal(getattr(streams, name).random(5), expected)


def test_streams_are_fresh_and_independent() -> None:
    a, b = seed_streams(7), seed_streams(7)
    np.testing.assert_array_equal(a.search.random(3), b.search.random(3))
    assert not np.array_equal(seed_streams(7).babbling.random(3), seed_streams(7).tracking.random(3))
