"""scripts/bench_scan.py scores both pipelines against exact float64 projections; here its ray–mesh
path lengths meet the analytic box chords of references/chords.py."""


def test_the_benchmark_reference_path_lengths_match_box_chords():
    from scripts.bench_scan import self_check

    assert self_check() < 1e-9  # mm, over every pixel of three views of an off-centre box
