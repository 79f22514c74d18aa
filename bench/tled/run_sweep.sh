#!/bin/sh
# tled_cpu speed/accuracy sweep on the spherical cavity (a = 10 mm, b = 20 mm,
# u(a) = 0.1 mm, nu = 0.49): node spacing h, support size K, time-step safety,
# integration-point spacing, nu, and the legacy supports (legacy=1: the K
# nearest nodes of each evaluation point) against the RMS / max error of u_r
# (relative to u(a)) and CPU time (columns: cavity_sweep.c).
# Usage (repo root, after `make build/plugins/tled_cpu.so`):
#   sh bench/tled/run_sweep.sh > bench/tled/sweep.tsv
# Single-threaded so that CPU times compare on a shared machine.
set -e
B=${BUILD:-build}
O=$B/obj/plugins/tled_cpu
mkdir -p $B/bench
cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime -Itests \
	-o $B/bench/tled_cavity_sweep bench/tled/cavity_sweep.c \
	$O/tled_model.o $O/tled_step.o $O/tled_solve.o -lm
X="env OMP_NUM_THREADS=1 $B/bench/tled_cavity_sweep threads=1"
$X header h=6 2>/dev/null
for h in 5 4.5 4 3.5 3 2.75 2.5 2.25 2; do $X h=$h 2>/dev/null || true; done
for K in 12 16 24 30 40; do $X h=3 K=$K 2>/dev/null || true; done
for s in 0.5 0.95; do $X h=3 safety=$s 2>/dev/null || true; done
for nu in 0.0 0.3 0.45 0.499; do $X h=3 nu=$nu 2>/dev/null || true; done
for ipf in 1.0 0.8; do $X h=3 ipf=$ipf 2>/dev/null || true; done
# nu 0 and 0.499 against h
for nu in 0.0 0.499; do for h in 4 2.5 2; do $X h=$h nu=$nu 2>/dev/null || true; done; done
# the legacy supports (K nearest of each evaluation point, ip_factor 1.0)
for nu in 0.0 0.49 0.499; do for h in 4 3 2.5 2; do
	$X h=$h nu=$nu legacy=1 ipf=1.0 2>/dev/null || true
done; done
