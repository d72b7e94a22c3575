// Function multiversioning for the hot loops of the package's libraries (gear_damping_id's
// integral method and quadrature, gear_sim_ros's bag reading).
//
// GEAR_AVX2_CLONES, put before a function definition, makes GCC compile the function twice, for
// AVX2 and for the baseline x86-64 (SSE2), and choose one when the library is loaded, by the CPU
// it runs on (target_clones: an ifunc resolver; every call, from any thread, takes that clone).
// It applies only to GCC on x86-64; other compilers (CI's clang build) and other architectures
// build the baseline function alone. AVX2 here is wider vectors only: no FMA is enabled (that is
// x86-64-v3, not the avx2 target), and without contraction or reassociation a loop whose lanes
// are independent accumulators, combined in a fixed order, computes the same bits in either
// clone. A function that should vectorise must still be written so (branch-free, no aliasing).
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define GEAR_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GEAR_AVX2_CLONES
#endif
