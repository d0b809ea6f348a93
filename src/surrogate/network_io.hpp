#pragma once
// Saving and loading a trained surrogate network as JSON (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training).
//
// Format (one object, format "trbc-mlp", version 1; version 2 = the same plus "ensemble"):
//   layer_sizes   [n_0, ..., n_L]
//   activation    "tanh" (hidden layers; output linear)
//   weights       L arrays; weights[l] has n_{l+1} rows of n_l numbers, W_l(i, j) = weights[l][i][j]
//   biases        L arrays; biases[l] has n_{l+1} numbers
//   input_mean, input_sd (n_0), output_mean, output_sd (n_L)   scaling of SURROGATE 3.2
//   input_names (n_0), output_names (n_L)                       strings
//   data_hash, command                                          strings
//   trbc_version                                                written for provenance, not read
//   split_seed                                                  unsigned integer
//   training      {batch_size, seed, train_fraction, test_fraction, test_seed, learning_rate,
//                  beta1, beta2, epsilon, patience, reduction_factor, max_reductions, max_epochs}
//   history       {train_loss, validation_loss, learning_rate (per epoch), reduction_epochs,
//                  restored_validation_loss, best_epoch, best_validation_loss, hit_epoch_cap,
//                  test_loss}; a NaN loss (no pass in the last epoch, no test set) is written as null
//   ensemble      optional: further members [{seed, best_validation_loss, weights, biases}, ...] with
//                 the same layer sizes, scalings and transforms; the network's output is the mean of
//                 all members' standardised outputs (TrainedNetwork)
// Doubles are written with the shortest representation that reads back exactly, so a loaded
// network gives bit-identical outputs.
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "surrogate/training.hpp"

namespace trbc {

/// JSON object of a trained network (format above).
nlohmann::json networkToJson(const TrainedNetwork& network);

/// Parse and validate; every problem throws InputError "<source>: key '<path>': <what is wrong>"
/// (missing keys, wrong types, wrong sizes, non-finite weights or scalings, SD <= 0, ...).
TrainedNetwork networkFromJson(const nlohmann::json& j, const std::string& source);

/// Write to `path` (InputError if the file cannot be written).
void saveNetwork(const TrainedNetwork& network, const std::string& path);

/// Read from `path`; InputError naming the file (and the key) on any problem.
TrainedNetwork loadNetwork(const std::string& path);

}  // namespace trbc
