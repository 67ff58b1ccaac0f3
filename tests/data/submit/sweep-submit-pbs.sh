#!/bin/bash
# Resubmits the jobs of the last `fiberform sweep --submit pbs` in the same order, with the same dependencies.
set -euo pipefail
cd @WORKDIR@
job_fabric=$(qsub @WORKDIR@/runs/pipe-sweep/jobs/fabric.pbs)
echo "fabric: job ${job_fabric}"
job_flow=$(qsub -W depend=afterok:${job_fabric} @WORKDIR@/runs/pipe-sweep/jobs/flow.pbs)
echo "flow: job ${job_flow}"
