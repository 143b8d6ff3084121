// Run-time choice of the kernel table: the best instruction set this build has and the CPU
// runs, unless SOFTBODY_SIMD (scalar, avx2, avx512, auto) or select_simd() says otherwise.
#include <atomic>
#include <cstdlib>
#include <string>
#include <vector>

#include "kernels.hpp"

#if defined(SOFTBODY_HAVE_X86_SIMD) && defined(_MSC_VER)
#include <intrin.h>
#include <immintrin.h>
#endif

namespace softbody {

namespace {

#if defined(SOFTBODY_HAVE_X86_SIMD) && defined(_MSC_VER)
// clang-cl on Windows: __builtin_cpu_supports needs compiler-rt, which the MSVC linker does
// not bring, so ask CPUID directly. An instruction set counts only when the processor has it
// and the operating system saves its registers (XCR0: SSE and AVX state for AVX2, and the
// opmask and ZMM state too for AVX-512), as __builtin_cpu_supports checks.
bool cpuid_runs(const std::string& name) {
    int r[4];
    __cpuid(r, 0);
    if (r[0] < 7) return false;
    __cpuidex(r, 1, 0);
    const bool fma = (r[2] & (1 << 12)) != 0, osxsave = (r[2] & (1 << 27)) != 0;
    if (!fma || !osxsave) return false;
    const unsigned long long xcr0 = _xgetbv(0);
    __cpuidex(r, 7, 0);
    const unsigned ebx = static_cast<unsigned>(r[1]);
    const bool avx2 = (ebx & (1u << 5)) != 0 && (xcr0 & 0x6) == 0x6;
    if (name == "avx2") return avx2;
    if (name == "avx512")
        return avx2 && (ebx & (1u << 16)) != 0 && (ebx & (1u << 17)) != 0 &&
               (ebx & (1u << 31)) != 0 && (xcr0 & 0xe6) == 0xe6;  // F, DQ, VL
    return false;
}
#endif

bool cpu_runs(const std::string& name) {
    if (name == "scalar") return true;
#if defined(SOFTBODY_HAVE_X86_SIMD) && defined(_MSC_VER)
    return cpuid_runs(name);
#elif defined(SOFTBODY_HAVE_X86_SIMD) && (defined(__GNUC__) || defined(__clang__))
    __builtin_cpu_init();
    if (name == "avx2") return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    if (name == "avx512")
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
               __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx2") &&
               __builtin_cpu_supports("fma");
#endif
    return false;
}

const KernelTable* table_named(const std::string& name) {
    if (name == "scalar") return &isa_scalar::kernel_table();
#ifdef SOFTBODY_HAVE_X86_SIMD
    if (name == "avx2") return &isa_avx2::kernel_table();
    if (name == "avx512") return &isa_avx512::kernel_table();
#endif
    return nullptr;
}

const KernelTable* best() {
    const auto names = available_simd();
    return table_named(names.back());
}

const KernelTable* initial() {
    const char* env = std::getenv("SOFTBODY_SIMD");
    if (env != nullptr && *env != '\0') {
        const std::string name(env);
        if (name != "auto" && cpu_runs(name) && table_named(name)) return table_named(name);
        // an unknown or unavailable name: the Python side reports it; run the best here
    }
    return best();
}

std::atomic<const KernelTable*>& current() {
    static std::atomic<const KernelTable*> table{initial()};
    return table;
}

}  // namespace

std::vector<std::string> available_simd() {
    std::vector<std::string> names;
    for (const char* name : {"scalar", "avx2", "avx512"})
        if (table_named(name) != nullptr && cpu_runs(name)) names.emplace_back(name);
    return names;
}

bool select_simd(const std::string& name) {
    const KernelTable* table = name == "auto" ? best() : nullptr;
    if (table == nullptr && cpu_runs(name)) table = table_named(name);
    if (table == nullptr) return false;
    current().store(table);
    return true;
}

const KernelTable& kernels() { return *current().load(); }

}  // namespace softbody
