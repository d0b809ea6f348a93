#pragma once
namespace trbc {
inline constexpr const char* kVersion = TRBC_VERSION;
}
