// Opt-in threads for the kernels, kept deterministic: work is cut into a fixed number of
// chunks (one per thread), each chunk writes only its own rows and its own partial sums,
// and partial sums are added in chunk order afterwards, so a run gives the same bits
// whatever the threads' timing. The pool itself lives in threads.hpp (plain C++, no instruction-set
// code); kernels see only this interface.
#pragma once

namespace softbody {

struct Parallel {
    int chunks = 1;  // threads, the caller's included
    /// Runs task(context, c) for every chunk c in [0, chunks) and returns when all are done.
    void (*run)(const Parallel& self, void (*task)(void* context, int chunk), void* context) =
        nullptr;
    void* pool = nullptr;  // the implementation's state
};

}  // namespace softbody
