// Run-time choice of the kernel table: the best instruction set this build has and the CPU
// runs, unless SOFTBODY_SIMD (scalar, avx2, avx512, auto) or select_simd() says otherwise.
#include <atomic>
#include <cstdlib>
#include <string>
#include <vector>

#include "kernels.hpp"

namespace softbody {

namespace {

bool cpu_runs(const std::string& name) {
    if (name == "scalar") return true;
#if defined(SOFTBODY_HAVE_X86_SIMD) && (defined(__GNUC__) || defined(__clang__))
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
