"""README's "Input errors, outputs and signals": every point it makes is
checked by named tests, and the numbers it states are the code's.

Each bullet of that section is a promise to users. The map below names,
for each bullet, the tests that would fail if the promise broke; this file
fails when the README gains a bullet no test stands behind, when a named
test is renamed or removed, or when a number in the text drifts from the
constant that enforces it.
"""

import re

import numpy as np
import pytest
from conftest import ROOT

from oclgi import budget, params, progress
from oclgi.cl import programs
from oclgi.errors import OclgiError
from oclgi.io import read_npy
from oclgi.scene import zip_reader

SECTION = "### Input errors, outputs and signals"

CHECKED_BY = {
    "One line, status 2.": [
        "test_fuzz.py::test_fuzz_toml", "test_fuzz.py::test_fuzz_dict", "test_fuzz.py::test_fuzz_cli",
        "test_bad_input.py", "test_environment.py::test_an_empty_icd_vendor_folder_is_named",
        "test_environment.py::test_a_kernel_syntax_error_is_one_line_naming_the_file",
    ],
    "Numbers in the device's precision.": [
        "test_formats.py::test_scene_values_beyond_float32_refused",
        "test_api_validation.py::test_radius_whose_resolve_underflows_is_refused",
        "test_api_validation.py::test_scene_built_in_python_is_checked_where_it_meets_the_engine",
        "test_api_validation.py::test_render_takes_numpy_numbers",
        "test_api_validation.py::test_engine_and_estimator_arguments",
    ],
    "Points are checked when they are made.": [
        "test_api_validation.py::test_query_points_refuse_non_real_arrays",
        "test_api_validation.py::test_query_points_refuse_wrong_shapes",
        "test_api_validation.py::test_float64_and_narrow_arrays_are_converted_by_value",
        "test_api_validation.py::test_query_points_refuse_bad_values",
        "test_api_validation.py::test_out_of_range_triangle_is_refused_not_a_crash",
        "test_api_validation.py::test_triangle_ids_checked_where_points_meet_the_engine",
    ],
    "Jobs too large are refused before any work": [
        "test_resources.py::test_huge_image_refused_with_its_estimate",
        "test_resources.py::test_one_buffer_too_large_is_enough_to_refuse",
        "test_resources.py::test_cpu_device_total_is_the_hosts_memory",
        "test_resources.py::test_study_seeds_refused_before_their_list",
        "test_resources.py::test_study_points_refused_before_they_are_drawn",
        "test_resources.py::test_animation_frames_capped_with_the_estimate",
        "test_resources.py::test_long_run_gives_a_time_estimate",
        "test_progress.py::test_progress_off_a_terminal_is_a_line_every_period_with_the_time_left",
    ],
    "Hostile files are bounded.": [
        "test_formats.py::test_zip_bound_covers_all_members_together",
        "test_formats.py::test_zip_header_that_lies_cannot_inflate_more",
        "test_formats.py::test_ply_counts_must_match_the_data",
        "test_formats.py::test_off_counts_must_match_the_data",
        "test_formats.py::test_ply_negative_face_index_refused",
        "test_formats.py::test_deeply_nested_toml_is_one_error",
        "test_guarantees.py::test_npy_header_is_checked_against_the_file",
    ],
    "Degenerate triangles": [
        "test_formats.py::test_huge_ground_plane_keeps_the_light",
        "test_formats.py::test_degeneracy_is_relative_to_each_triangle",
        "test_formats.py::test_slivers_and_zero_area_triangles_still_dropped_beside_a_huge_plane",
    ],
    "Output files are whole or absent.": [
        "test_outputs.py::test_full_disk_is_an_error_and_leaves_no_file",
        "test_outputs.py::test_full_disk_cli_render",
        "test_outputs.py::test_written_files_are_checked_whole",
        "test_outputs.py::test_sigterm_while_writing_leaves_no_temporary_file",
        "test_outputs.py::test_sigkill_leftover_is_removed_by_the_next_run",
        "test_outputs.py::test_temporary_names_carry_the_pid",
    ],
    "Nothing is replaced by surprise.": [
        "test_outputs.py::test_sibling_never_replaces_a_users_file",
        "test_outputs.py::test_sibling_of_a_png_and_reruns",
        "test_outputs.py::test_default_outputs_are_both_protected",
        "test_outputs.py::test_irradiance_output_is_not_the_points_file",
        "test_outputs.py::test_render_output_is_not_the_scene_file",
        "test_outputs.py::test_animate_output_is_not_the_keyframes_file",
        "test_outputs.py::test_read_only_places_fail_before_any_work",
        "test_outputs.py::test_failed_animation_adds_no_frame",
    ],
    "Ctrl-C": [
        "test_signals.py::test_ctrl_c_while_importing_is_one_line_and_130",
        "test_signals.py::test_ctrl_c_during_a_long_kernel_exits_within_a_second",
        "test_signals.py::test_repeated_ctrl_c_is_still_one_line_and_130",
        "test_signals.py::test_ctrl_c_during_a_cold_kernel_build",
        "test_signals.py::test_a_run_started_with_sigint_ignored_ignores_it_during_cold_builds",
    ],
    "Standard output.": [
        "test_signals.py::test_closed_stdout_pipe_ends_quietly_with_141",
        "test_signals.py::test_full_stdout_is_one_line_and_status_2",
    ],
}


def _section() -> str:
    text = (ROOT / "README.md").read_text()
    start = text.index(SECTION)
    end = text.find("\n## ", start)
    return text[start:end if end >= 0 else None]


def _bullets() -> list[str]:
    return re.findall(r"^- \*\*(.+?)\*\*", _section(), flags=re.MULTILINE)


def test_every_promise_has_its_tests():
    assert _bullets() == list(CHECKED_BY)


def test_the_named_tests_exist():
    for tests in CHECKED_BY.values():
        for ref in tests:
            file, _, name = ref.partition("::")
            source = (ROOT / "tests" / file).read_text()
            if name:
                assert re.search(rf"^(def {name}\(|{name} = )", source, flags=re.MULTILINE), f"{ref} is gone"
            else:
                assert "def test_" in source


def test_the_numbers_are_the_codes():
    text = " ".join(_section().split())
    assert f"up to {params.MAX_IMAGE_SIDE} a side" in text
    assert params.MAX_FRAMES == 10**6 and "frames (up to 10^6)" in text
    assert zip_reader.MAX_INFLATED == 1 << 30 and "inflate to 1 GiB in all" in text
    assert progress.PERIOD == 10.0 and "a line every 10 s" in text
    assert programs.SLICE_SECONDS == 0.1 and "slices of about 0.1 s" in text
    assert budget.NOTICE_SECONDS == 60.0 and "more than a minute" in text


def test_npy_header_is_checked_against_the_file(tmp_path):
    """A header claiming terabytes is refused before numpy allocates them;
    a truncated file is refused; a Fortran-ordered float32 file reads."""
    huge = tmp_path / "huge.npy"
    with open(huge, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (300_000_000_000, 6)})
        f.write(bytes(48))
    with pytest.raises(OclgiError, match=r"declares shape \(300000000000, 6\) .* holds 48 bytes"):
        read_npy(huge, "points")
    ok = np.asfortranarray(np.arange(12, dtype=np.float32).reshape(2, 6))
    np.save(tmp_path / "ok.npy", ok)
    assert np.array_equal(read_npy(tmp_path / "ok.npy", "points"), ok)
    (tmp_path / "cut.npy").write_bytes((tmp_path / "ok.npy").read_bytes()[:-4])
    with pytest.raises(OclgiError, match="holds 44 bytes"):
        read_npy(tmp_path / "cut.npy", "points")
    np.save(tmp_path / "obj.npy", np.array([{}], object), allow_pickle=True)
    with pytest.raises(OclgiError, match="expected points as numbers"):
        read_npy(tmp_path / "obj.npy", "points")
