#pragma once
// The instruction-set path of the kernels that trbc dispatches at run time (docs/PERFORMANCE.md,
// portable build): the default build targets baseline x86-64, and the kernels that gain from wider
// vectors are also compiled for AVX2 + FMA and chosen when the CPU offers it.
#include <string>
#include <string_view>

namespace trbc::simd {

enum class Path { portable, avx2 };

/// "portable", "avx2".
std::string_view name(Path p);
/// Whether this CPU runs the path (portable: always).
bool cpuOffers(Path p);
/// The path the dispatched kernels take now: the widest the CPU offers, unless TRBC_SIMD (one of
/// the names) or force() said otherwise.
Path active();
/// Forces a path (tests compare each path's results with the portable one's). Throws InputError
/// when the CPU does not offer it.
void force(Path p);
/// Parses a path name; throws InputError naming `option` and the valid names.
Path parse(std::string_view text, std::string_view option);
/// The compiler and the instruction set the build targets, for the provenance of records:
/// e.g. "GCC 12.2.0, x86-64 (dispatch: avx2)" or "GCC 12.2.0, -march=native (AVX2 FMA)".
std::string buildTarget();

}  // namespace trbc::simd
