#pragma once
#include <nlohmann/json.hpp>

namespace trbc {
inline constexpr const char* kVersion = TRBC_VERSION;
/// The source revision of this build: `git describe --always --dirty` of the checkout at build time,
/// "unknown" outside a git checkout (cmake/git_describe.cmake writes it before each build).
const char* gitDescribe();
/// `record` with this binary's identity added, for the provenance of every JSON record: "version",
/// "revision" (gitDescribe) and "build" (the compiler and instruction set, simd::buildTarget).
nlohmann::json withBuild(nlohmann::json record);
/// Revision of the forward model's outputs (docs/FORWARD_MODEL.md) within one version: campaigns and
/// `trbc simulate` record it, and a campaign refuses to resume across it, so that rows of two
/// revisions never mix.
///   1: first release;
///   2: the relaxation's deformation index z = L/W from the extents sorted in decreasing order
///      (relaxation), not in the order of the principal axes (which swapped L and W near a round shape).
inline constexpr int kForwardModelRevision = 2;
}  // namespace trbc
