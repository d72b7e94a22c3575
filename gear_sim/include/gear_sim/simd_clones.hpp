// Function multiversioning for the hot loops of the package's libraries (gear_damping_id's
// integral method, quadrature, refinement and wavelet rows, gear_sim's block passes,
// gear_sim_ros's bag reading).
//
// GEAR_AVX2_CLONES, put before a function definition, makes GCC compile the function twice, for
// AVX2 and for the baseline x86-64 (SSE2), and choose one when the library is loaded, by the CPU
// it runs on (target_clones: an ifunc resolver; every call, from any thread, takes that clone).
// It applies only to GCC on x86-64; other compilers (CI's clang build) and other architectures
// build the baseline function alone. AVX2 here is wider vectors only: no FMA is enabled (that is
// x86-64-v3, not the avx2 target), and without contraction or reassociation a loop whose lanes
// are independent accumulators, combined in a fixed order, computes the same bits in either
// clone. A function that should vectorise must still be written so (branch-free, no aliasing).
//
// GEAR_FMA_CLONES: the same for x86-64-v4 (AVX-512), x86-64-v3 (AVX2 + FMA) and the baseline. GCC
// contracts multiply-adds into FMA in the v3 and v4 clones, so they agree with the baseline to
// rounding, not in every bit: only for loops under a numeric contract that allows it
// (docs/method.md). The v4 clone runs the same code with the same 4-lane vectors and the same
// contractions as v3 (the same bits, checked on held-out records); it gains AVX-512's 32 vector
// registers, so the refinement's fused passes and the greybox Gram keep their accumulators in
// registers (docs/performance.md). On one machine every run and every thread takes the same
// clone, so results do not depend on the run or the thread count.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define GEAR_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#define GEAR_FMA_CLONES \
  __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define GEAR_AVX2_CLONES
#define GEAR_FMA_CLONES
#endif
