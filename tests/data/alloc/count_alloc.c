/* A malloc counter for tests/test_allocations.py, preloaded with LD_PRELOAD (glibc only).
 *
 * Every allocation function forwards to glibc's own (__libc_malloc, ...); while a thread has
 * called sofac_alloc_count_start(), its calls are counted (C++'s operator new ends in malloc, and
 * so do CHOLMOD's and Eigen's allocations). sofac_alloc_count_stop() returns the count. */
#define _GNU_SOURCE
#include <errno.h>
#include <stddef.h>

extern void* __libc_malloc(size_t size);
extern void* __libc_calloc(size_t count, size_t size);
extern void* __libc_realloc(void* pointer, size_t size);
extern void* __libc_memalign(size_t alignment, size_t size);

static __thread int counting;
static __thread long counted;

void sofac_alloc_count_start(void) {
    counted = 0;
    counting = 1;
}

long sofac_alloc_count_stop(void) {
    counting = 0;
    return counted;
}

void* malloc(size_t size) {
    if (counting) ++counted;
    return __libc_malloc(size);
}

void* calloc(size_t count, size_t size) {
    if (counting) ++counted;
    return __libc_calloc(count, size);
}

void* realloc(void* pointer, size_t size) {
    if (counting) ++counted;
    return __libc_realloc(pointer, size);
}

void* memalign(size_t alignment, size_t size) {
    if (counting) ++counted;
    return __libc_memalign(alignment, size);
}

void* aligned_alloc(size_t alignment, size_t size) {
    if (counting) ++counted;
    return __libc_memalign(alignment, size);
}

int posix_memalign(void** out, size_t alignment, size_t size) {
    if (counting) ++counted;
    void* pointer = __libc_memalign(alignment, size);
    if (!pointer) return ENOMEM;
    *out = pointer;
    return 0;
}
