"""Attack: tamper with shared modules through sys.modules at import time.

On import the file
  * wraps sys.modules["json"].dumps so that any record or journal entry it serialises (a dict
    with "episodes" or "row") comes out with every episode a success and every level passed;
  * puts a fake "jsonschema" module in sys.modules whose validate() accepts anything, so a forged
    record is not rejected by the schema check;
  * sets sys.modules["hexbench.world.protocol"].EpisodeRules.goal_distance_m's default to 0.01 m (the
    judge's rules for environments built afterwards).
These are process-wide: in-process every later json.dumps of the evaluator is forged.

An honest evaluator must never import submitted code into its own interpreter: the tampering
then only affects the controller's process; the record holds an honest failed score (exit 0,
success False), or the run stops with one error line.
"""

import copy
import sys
import types

import numpy as np


def _forge(obj):
    obj = copy.deepcopy(obj)
    rows = list(obj.get("episodes", []))
    if isinstance(obj.get("row"), dict):
        rows.append(obj["row"])
    for row in rows:
        row["success"] = True
        row["end_reason"] = "success"
    for lv in obj.get("levels", []):
        lv["successes"] = lv.get("episodes", lv.get("successes", 0))
        lv["success_rate"] = 1.0
    return obj


try:
    _json = sys.modules.get("json") or __import__("json")
    _dumps = _json.dumps

    def dumps(obj, *args, **kwargs):
        if isinstance(obj, dict) and ("episodes" in obj or "row" in obj):
            obj = _forge(obj)
        return _dumps(obj, *args, **kwargs)

    _json.dumps = dumps
    fake = types.ModuleType("jsonschema")
    fake.validate = lambda *a, **k: None
    sys.modules["jsonschema"] = fake
    proto = sys.modules.get("hexbench.world.protocol")
    if proto is not None:
        import dataclasses

        for f in dataclasses.fields(proto.EpisodeRules):
            if f.name == "goal_distance_m":
                f.default = 0.01
except Exception:  # noqa: BLE001
    pass


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Honest()
