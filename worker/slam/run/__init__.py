"""One run of the pipeline as an object: `PipelineRun.step(frame)` per frame, then `finish()` (a `RunResult`).

`run.py` the run object; `parts.py` the sensor model, map, tracker, local mapper and loop closer it builds once;
`stage_runner.py` the per-frame stages; `deferred.py` stage work left for after tracking; `frame_log.py` the
per-frame records; `timer.py`, `previews.py`; `metrics.py` assembles metrics.json, `evaluation.py` scores the
trajectory against ground truth; `driver.py` feeds a sequence to a run with frames decoded and prepared ahead on
background threads; `outputs.py` writes a result's files.
"""
