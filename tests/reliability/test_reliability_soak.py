"""The short soak of CI: 20 s of mixed, deliberately overloading load on `fishloc serve` over
loopback (the long run is `python tests/reliability/reliability_soak.py --minutes 30`)."""

from __future__ import annotations

from pathlib import Path

from reliability_soak import SoakConfig, run_soak


def test_short_soak(tmp_path: Path) -> None:
    config = SoakConfig(seconds=20, clients=6, max_in_flight=2)
    report = run_soak(config, tmp_path)
    assert report.unanswered == 0 and report.requests > 50
    assert not report.bad_answers, report.bad_answers[:5]
    assert set(report.statuses) <= {"200", "400", "415", "422", "503"}
    assert report.statuses.get("200", 0) > 0
    assert report.statuses.get("503", 0) > 0  # the overload was real, and answered 503 + Retry-After
    assert len(report.rss_samples_kib) >= 10
    assert report.rss_late_kib <= report.rss_early_kib * (1 + config.rss_margin) + config.rss_slack_kib, (
        report.rss_early_kib, report.rss_late_kib)
