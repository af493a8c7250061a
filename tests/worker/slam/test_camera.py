import pytest

from worker.slam.camera import PRESETS, Camera, parse_camera
from worker.slam.errors import CameraError


def test_presets_have_documented_values():
    assert PRESETS["7scenes"].depth_scale == 1000 and PRESETS["7scenes"].fx == 585
    assert PRESETS["bonn"].fx == pytest.approx(542.822841) and PRESETS["tum3"].depth_scale == 5000


def test_parse_explicit_json_with_four_dist():
    cam = parse_camera('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "dist": [0.1, 0, 0, 0]}')
    assert cam.dist == (0.1, 0.0, 0.0, 0.0, 0.0) and cam.K[0, 0] == 500


def test_only_seven_scenes_ships_depth_not_registered_to_colour():
    assert [name for name, cam in PRESETS.items() if not cam.depth_registered] == ["7scenes"]
    cam = parse_camera('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "depth_registered": false}')
    assert not cam.depth_registered and Camera.from_dict(cam.to_dict()) == cam
    assert parse_camera('{"fx": 500, "fy": 500, "cx": 320, "cy": 240}').depth_registered


@pytest.mark.parametrize("spec", ["nope", '{"fx": -1, "fy": 1, "cx": 1, "cy": 1}', '{"fx": 1', '{"f": 1}',
                                  '{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "depth_registered": "no"}'])
def test_bad_camera(spec):
    with pytest.raises(CameraError):
        parse_camera(spec)
