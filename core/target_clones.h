// SWARF_TARGET_CLONES: marks a function to be compiled for wider vectors
// too (AVX2, AVX-512), one clone picked at load time. Every clone does the
// same IEEE operations (no FMA: -ffp-contract=off), so the same bits.
// SWARF_NO_TARGET_CLONES keeps only the default: clang 14 names the ifunc
// "<name>.ifunc", so callers in other files don't link (fuzz builds).
// SWARF_NO_AVX512_CLONES keeps the default and AVX2 (a build to compare
// with on a machine whose cores slow down under AVX-512).
#ifndef SWARF_CORE_TARGET_CLONES_H_
#define SWARF_CORE_TARGET_CLONES_H_

#ifdef SWARF_NO_TARGET_CLONES
#define SWARF_TARGET_CLONES
#elif defined(SWARF_NO_AVX512_CLONES)
#define SWARF_TARGET_CLONES __attribute__((target_clones("default", "avx2")))
#else
#define SWARF_TARGET_CLONES \
  __attribute__((target_clones("default", "avx2", "arch=x86-64-v4")))
#endif

#endif  // SWARF_CORE_TARGET_CLONES_H_
