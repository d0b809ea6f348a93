#include "core/simd.hpp"

#include <fmt/format.h>

#include <atomic>
#include <cstdlib>

#include "core/error.hpp"

namespace trbc::simd {
namespace {

Path widestOffered() { return cpuOffers(Path::avx2) ? Path::avx2 : Path::portable; }

// The active path: decided once (TRBC_SIMD, else the CPU), changed only by force().
std::atomic<Path>& current() {
    static std::atomic<Path> p = [] {
        const char* env = std::getenv("TRBC_SIMD");
        if (env == nullptr || *env == '\0') return widestOffered();
        const Path wanted = parse(env, "environment variable TRBC_SIMD");
        if (!cpuOffers(wanted))
            throw InputError(fmt::format("environment variable TRBC_SIMD={}: this CPU does not offer it (valid here: portable{})",
                                           env, cpuOffers(Path::avx2) ? ", avx2" : ""));
        return wanted;
    }();
    return p;
}

}  // namespace

std::string_view name(Path p) { return p == Path::avx2 ? "avx2" : "portable"; }

bool cpuOffers(Path p) {
    if (p == Path::portable) return true;
#if defined(__x86_64__) && defined(__GNUC__)
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return false;
#endif
}

Path active() { return current().load(std::memory_order_relaxed); }

void force(Path p) {
    if (!cpuOffers(p)) throw InputError(fmt::format("SIMD path {}: this CPU does not offer it", name(p)));
    current().store(p, std::memory_order_relaxed);
}

Path parse(std::string_view text, std::string_view option) {
    for (Path p : {Path::portable, Path::avx2})
        if (text == name(p)) return p;
    throw InputError(fmt::format("{}: '{}' is not a SIMD path (valid: portable, avx2)", option, text));
}

std::string buildTarget() {
#if defined(__clang__)
    const std::string compiler = fmt::format("Clang {}.{}.{}", __clang_major__, __clang_minor__, __clang_patchlevel__);
#elif defined(__GNUC__)
    const std::string compiler = fmt::format("GCC {}.{}.{}", __GNUC__, __GNUC_MINOR__, __GNUC_PATCHLEVEL__);
#else
    const std::string compiler = "unknown compiler";
#endif
#if defined(TRBC_NATIVE_BUILD)
    const std::string target = "-march=native";
#elif defined(__x86_64__)
    const std::string target = "x86-64";
#else
    const std::string target = "generic";
#endif
#if defined(__AVX512F__)
    const char* isa = "AVX-512";
#elif defined(__AVX2__)
    const char* isa = "AVX2";
#elif defined(__AVX__)
    const char* isa = "AVX";
#else
    const char* isa = "SSE2";
#endif
    return fmt::format("{}, {} ({} baseline; dispatched kernels: {})", compiler, target, isa, name(active()));
}

}  // namespace trbc::simd
