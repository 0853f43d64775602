"""``rcp bench accuracy`` on a tiny sweep: the report's shape, the Pareto front, and the chart file."""

import json

import pytest

from rcp_server.bench.accuracy import Sweep, pareto, run


def test_pareto_front_keeps_only_points_nothing_beats_on_both_time_and_quality():
    points = [{"ms": 1, "psnr": 20}, {"ms": 2, "psnr": 19}, {"ms": 3, "psnr": 25}, {"ms": 3, "psnr": 24}]
    assert pareto(points, "psnr") == [points[0], points[2]]


def test_accuracy_report_and_chart(tmp_path):
    pytest.importorskip("matplotlib")
    sweep = Sweep(32, 18, (1, 2), (1.0, 0.5), 8, 1)
    report = run(tmp_path, scenes=("sky",), sweep=sweep, threads=2)
    saved = json.loads((tmp_path / "accuracy.json").read_text())
    assert saved["points"] == report["points"] and len(saved["points"]) == 2 * 2 * 2  # methods, spps, scales
    for p in saved["points"]:
        assert {"method", "spp", "scale", "ms", "psnr", "ssim", "psnr_edge", "ssim_edge"} <= set(p)
        assert p["ms"] > 0 and 0 < p["psnr"] <= 100 and -1 <= p["ssim"] <= 1
    one = {(p["method"], p["scale"]): p for p in saved["points"] if p["spp"] == 1}
    assert one["raytrace", 1.0]["psnr"] > one["raytrace", 0.5]["psnr"]  # full resolution, closer to the reference
    assert one["raytrace", 1.0]["psnr"] > one["image", 1.0]["psnr"]  # the image method's bilinear bias
    assert (tmp_path / "accuracy.png").read_bytes()[:4] == b"\x89PNG"
