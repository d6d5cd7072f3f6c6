"""Fuzzing, the bounded sample run by ``make test`` (bench/fuzz.py runs the long campaign).

Every format of tests/fuzz/strategies.py draws a fixed, derandomized set of
cases (no example database: the same cases on every machine) and each must
pass tests/fuzz/oracle.py's judgement: exit 0 with complete, readable
outputs, or exit 2 with one ``oclgi: error:`` line and nothing written; never
a traceback, a crash, a hang or a partial file. Cases run in one worker
process (in-process calls, one kernel compile), so a crash fails its case,
not the session. On a failure hypothesis shrinks the case; the message shows
the command and its stderr.
"""

import pytest
from fuzz.oracle import Runner
from fuzz.strategies import FORMATS
from hypothesis import HealthCheck, given, settings

# Cases per format in `make test`: 200 in all, about 10 s on two cores when
# they pass; parse-level formats (dict, cli) get more, the ones that mostly
# reach the device (obj, mtl) fewer. The full suite runs four times as many
# (``*_campaign``), and bench/fuzz.py the long campaign.
EXAMPLES = {"toml": 30, "dict": 75, "obj": 12, "mtl": 5, "ply": 12, "gltf": 20, "points": 15, "cli": 30}
CAMPAIGN = 4


@pytest.fixture(scope="module")
def runner(tmp_path_factory):
    r = Runner(tmp_path_factory.mktemp("fuzz"))
    r.reproducers = tmp_path_factory.mktemp("fuzz-reproducers")
    yield r
    r.close()


def _fuzz(fmt, scale=1):
    @settings(max_examples=EXAMPLES[fmt] * scale, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(case=FORMATS[fmt])
    def test(runner, case):
        outcome = runner.run(case)
        if not outcome.ok:
            # the last one saved is hypothesis' shrunk example, the one it reports
            saved = case.save(runner.reproducers / fmt, outcome)
            raise AssertionError(f"{outcome.describe()}\nreproducer: {saved} "
                                 f"(python bench/fuzz.py --replay {saved})")

    test.__name__ = f"test_fuzz_{fmt}" + ("_campaign" if scale > 1 else "")
    test.__doc__ = f"Generated {fmt} cases fail cleanly or succeed completely."
    return test if scale == 1 else pytest.mark.full(test)


test_fuzz_toml = _fuzz("toml")
test_fuzz_dict = _fuzz("dict")
test_fuzz_obj = _fuzz("obj")
test_fuzz_mtl = _fuzz("mtl")
test_fuzz_ply = _fuzz("ply")
test_fuzz_gltf = _fuzz("gltf")
test_fuzz_points = _fuzz("points")
test_fuzz_cli = _fuzz("cli")
for _fmt in EXAMPLES:  # the full suite's four-times-larger sample
    globals()[f"test_fuzz_{_fmt}_campaign"] = _fuzz(_fmt, CAMPAIGN)
