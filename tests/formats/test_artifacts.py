from formats import artifacts


def test_frame_image_names_round_trip():
    name = artifacts.frame_image(12, "restored")
    assert name == "frame_000012_restored.jpg"
    assert artifacts.parse_frame_image(name) == (12, "restored")
    assert artifacts.parse_frame_image("frame_1234567_rgb.png") == (1234567, "rgb")


def test_other_names_are_not_frame_images():
    for name in (artifacts.TRAJECTORY, artifacts.PREVIEW, "frame_12_rgb.jpg", "frame_000001_rgb.txt"):
        assert artifacts.parse_frame_image(name) is None


def test_pipeline_outputs_are_distinct_plain_names():
    names = [*artifacts.PIPELINE_OUTPUTS, artifacts.FRAME_STATS, artifacts.LOG, artifacts.PREVIEW,
             artifacts.GROUNDTRUTH_ALIGNED, *artifacts.FIGURES]
    assert len(set(names)) == len(names)
    assert all("/" not in n and not n.startswith(".") for n in names)


def test_figures_are_pngs_the_job_page_tells_from_frame_images():
    for name in artifacts.FIGURES:
        assert name.startswith("plot_") and name.endswith(".png")  # webui/static/js/job.js isFigure
        assert artifacts.parse_frame_image(name) is None
