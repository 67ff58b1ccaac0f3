#!/bin/bash
# Resubmits the jobs of the last `fiberform submit --scheduler pbs` in the same order, with the same dependencies.
set -euo pipefail
cd @WORKDIR@
job_fabric=$(qsub @WORKDIR@/runs/pipe/jobs/fabric.pbs)
echo "fabric: job ${job_fabric}"
job_flow=$(qsub -W depend=afterok:${job_fabric} @WORKDIR@/runs/pipe/jobs/flow.pbs)
echo "flow: job ${job_flow}"
