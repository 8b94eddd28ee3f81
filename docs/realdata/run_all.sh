#!/bin/sh
# Reproduces every number in docs/REALDATA_FINDINGS.md (about 1 min on one core).
cd "$(dirname "$0")"
export OPENBLAS_NUM_THREADS=1 PYTHONPATH="$(cd ../.. && pwd):$(pwd)"
nice python tofu.py x > out_tofu_x.txt
nice python tofu.py y > out_tofu_y.txt
nice python extra.py > /dev/null
nice python legdiff.py > out_legdiff.txt
nice python labelcheck.py > out_labelcheck.txt
nice python psim_allan.py 2>/dev/null > /dev/null
nice python perleg.py > out_perleg.txt
nice python table.py > out_table.md
nice python acchyst.py > out_acchyst.txt
python tauscan.py > out_tauscan.txt
nice python combos.py > out_combos.txt
python estim.py > out_estim.txt
