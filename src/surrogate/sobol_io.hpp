#pragma once
// CSV output of Sobol' indices (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices: first-order and total indices with their
// confidence intervals are stored). Values are written with 17 significant digits (round trip).
#include <filesystem>

#include "surrogate/sobol.hpp"

namespace trbc {

/// One row per (output, input): header `output,input,S1,S1_ci,ST,ST_ci`, outputs in result order,
/// inputs in order within each output. Names must not contain ',', '"' or line breaks
/// (InputError); InputError if the file cannot be written.
void writeSobolCsv(const std::filesystem::path& path, const SobolResult& result);

/// Second-order indices, one row per output and pair i < j: header `output,input_i,input_j,S2,S2_ci`.
/// InputError if the result has no second-order indices or the file cannot be written.
void writeSobolSecondOrderCsv(const std::filesystem::path& path, const SobolResult& result);

}  // namespace trbc
