"""tests/domains.py: a DDS domain claimed by one process is not handed to another (two suites run
at once on one machine never share a domain), and is free again once released or its holder
ends."""
import subprocess
import sys
from pathlib import Path

import domains

CLAIM = [sys.executable, '-c', 'import sys; sys.path.insert(0, sys.argv[1]); import domains; '
         'print(domains.claim(int(sys.argv[2])))', str(Path(domains.__file__).parent)]


def _claim_elsewhere(preferred: int) -> int:
    return int(subprocess.run(CLAIM + [str(preferred)], capture_output=True, text=True,
                              check=True, timeout=30).stdout)


def test_a_claimed_domain_is_not_given_to_another_process_until_released():
    d = domains.claim(77)
    try:
        assert d in domains.held()
        other = _claim_elsewhere(d)
        assert other != d and 1 <= other <= 101
        # the same process never gets it twice either
        again = domains.claim(d)
        assert again != d
        domains.release(again)
    finally:
        domains.release(d)
    # released (the other process has ended too): free for the next one
    assert _claim_elsewhere(d) == d
    assert d not in domains.held()


def test_claims_wrap_within_1_to_101():
    d = domains.claim(101 + 5)
    try:
        assert 1 <= d <= 101
    finally:
        domains.release(d)


def test_a_domain_claimed_for_a_block_is_given_back_when_it_ends():
    with domains.claimed(77) as d:
        assert d in domains.held() and _claim_elsewhere(d) != d
    assert d not in domains.held() and _claim_elsewhere(d) == d
