/*
 * A fake CUDA driver (libcuda.so.1) for benchmarks/registers.py: it lets Taichi's CUDA backend start
 * and JIT-compile its kernels to PTX on a machine without a GPU, so that NVIDIA's ptxas can report the
 * registers, spills, stack and shared memory of each compiled kernel. It measures compiled kernels
 * only: it is never a driver to run anything with. Nothing computed on it is right.
 *
 * It pretends to be one NVIDIA H200: compute capability 9.0 (sm_90), 132 SMs, 1024 threads and
 * 64 Ki registers a block, 2048 threads, 32 blocks, 64 Ki registers and 228 KiB of shared memory an
 * SM (227 KiB a block opted in), 140 GiB of memory; driver API 12.4.
 *
 * Every call succeeds (once CUDASTUB_DIR is set). Kernel launches do nothing. Device memory is host
 * memory (anonymous zero-filled mappings), so copies and memsets are real host copies and memsets, and
 * what the host reads back is what it wrote or zeros.
 *
 * CUDASTUB_DIR (required; there is no default) receives
 *   ptx/module_NNNN.ptx  each PTX image given to cuModuleLoadDataEx, numbered in the order loaded;
 *   launches.log         one line a launch: "module NNNN <kernel> grid=X,Y,Z block=X,Y,Z shmem=N".
 * Without it, or where ptx/ cannot be made, cuInit fails (CUDA_ERROR_NOT_INITIALIZED) and says why
 * on stderr, so that nothing runs on the stub unawares and nothing is written anywhere else.
 *
 * It defines the driver functions Taichi 1.7.4 loads (all of them, or Taichi refuses the library)
 * and those pbf.solver.backend calls itself (cuDeviceTotalMem_v2).
 *
 * Build: cc -O2 -shared -fPIC -Wl,-soname,libcuda.so.1 -o libcuda.so.1 cuda_stub.c
 *        ln -s libcuda.so.1 libcuda.so     (Taichi opens libcuda.so)
 */
#define _GNU_SOURCE
#include <errno.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>

typedef int CUresult;
#define CUDA_SUCCESS 0
#define CUDA_ERROR_OUT_OF_MEMORY 2
#define CUDA_ERROR_NOT_INITIALIZED 3
#define CUDA_ERROR_OPERATING_SYSTEM 304
#define API __attribute__((visibility("default")))

#define PAGE ((size_t)4096)
#define MEMORY_BYTES 150754820096ull /* the H200's 140 GiB */

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static char ptx_dir[4096];
static FILE *launches;
static int modules_loaded;

/* ---------------------------------------------------------------------------------- driver */

API CUresult cuInit(unsigned flags) {
  (void)flags;
  CUresult result = CUDA_SUCCESS;
  pthread_mutex_lock(&lock);
  if (!launches) {
    const char *dir = getenv("CUDASTUB_DIR");
    char path[4096];
    if (!dir || !*dir) {
      fprintf(stderr, "cuda_stub: CUDASTUB_DIR is not set: the fake CUDA driver has nowhere to write\n");
      result = CUDA_ERROR_NOT_INITIALIZED;
    } else if (strlen(dir) > sizeof ptx_dir - 32) {
      fprintf(stderr, "cuda_stub: CUDASTUB_DIR is too long\n");
      result = CUDA_ERROR_NOT_INITIALIZED;
    } else if (snprintf(ptx_dir, sizeof ptx_dir, "%s/ptx", dir), mkdir(ptx_dir, 0755) != 0 && errno != EEXIST) {
      fprintf(stderr, "cuda_stub: cannot make %s: %s\n", ptx_dir, strerror(errno));
      result = CUDA_ERROR_NOT_INITIALIZED;
    } else {
      snprintf(path, sizeof path, "%s/launches.log", dir);
      launches = fopen(path, "a");
      if (!launches) {
        fprintf(stderr, "cuda_stub: cannot open %s: %s\n", path, strerror(errno));
        result = CUDA_ERROR_NOT_INITIALIZED;
      }
    }
  }
  pthread_mutex_unlock(&lock);
  return result;
}

API CUresult cuDriverGetVersion(int *version) {
  *version = 12040;
  return CUDA_SUCCESS;
}

API CUresult cuGetErrorName(CUresult error, const char **name) {
  switch (error) {
    case CUDA_SUCCESS: *name = "CUDA_SUCCESS"; break;
    case CUDA_ERROR_OUT_OF_MEMORY: *name = "CUDA_ERROR_OUT_OF_MEMORY"; break;
    case CUDA_ERROR_NOT_INITIALIZED: *name = "CUDA_ERROR_NOT_INITIALIZED"; break;
    default: *name = "CUDA_ERROR_OPERATING_SYSTEM";
  }
  return CUDA_SUCCESS;
}

API CUresult cuGetErrorString(CUresult error, const char **text) {
  switch (error) {
    case CUDA_SUCCESS: *text = "no error"; break;
    case CUDA_ERROR_OUT_OF_MEMORY: *text = "the fake CUDA driver could not map host memory"; break;
    case CUDA_ERROR_NOT_INITIALIZED: *text = "the fake CUDA driver needs CUDASTUB_DIR (see stderr)"; break;
    default: *text = "the fake CUDA driver could not write a PTX module to CUDASTUB_DIR/ptx";
  }
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- device */

API CUresult cuDeviceGetCount(int *count) {
  *count = 1;
  return CUDA_SUCCESS;
}

API CUresult cuDeviceGet(int *device, int ordinal) {
  (void)ordinal;
  *device = 0;
  return CUDA_SUCCESS;
}

API CUresult cuDeviceGetName(char *name, int length, int device) {
  (void)device;
  snprintf(name, length, "NVIDIA H200");
  return CUDA_SUCCESS;
}

API CUresult cuDeviceTotalMem_v2(size_t *bytes, int device) {
  (void)device;
  *bytes = MEMORY_BYTES;
  return CUDA_SUCCESS;
}

API CUresult cuDeviceGetAttribute(int *value, unsigned attribute, int device) {
  (void)device;
  switch (attribute) { /* CUdevice_attribute; the rest are 0 */
    case 1: *value = 1024; break;       /* MAX_THREADS_PER_BLOCK */
    case 2: *value = 1024; break;       /* MAX_BLOCK_DIM_X */
    case 3: *value = 1024; break;       /* MAX_BLOCK_DIM_Y */
    case 4: *value = 64; break;         /* MAX_BLOCK_DIM_Z */
    case 5: *value = 2147483647; break; /* MAX_GRID_DIM_X */
    case 6: *value = 65535; break;      /* MAX_GRID_DIM_Y */
    case 7: *value = 65535; break;      /* MAX_GRID_DIM_Z */
    case 8: *value = 49152; break;      /* MAX_SHARED_MEMORY_PER_BLOCK */
    case 9: *value = 65536; break;      /* TOTAL_CONSTANT_MEMORY */
    case 10: *value = 32; break;        /* WARP_SIZE */
    case 12: *value = 65536; break;     /* MAX_REGISTERS_PER_BLOCK */
    case 13: *value = 1980000; break;   /* CLOCK_RATE, kHz */
    case 16: *value = 132; break;       /* MULTIPROCESSOR_COUNT */
    case 19: *value = 1; break;         /* CAN_MAP_HOST_MEMORY */
    case 31: *value = 1; break;         /* CONCURRENT_KERNELS */
    case 39: *value = 2048; break;      /* MAX_THREADS_PER_MULTIPROCESSOR */
    case 41: *value = 1; break;         /* UNIFIED_ADDRESSING */
    case 75: *value = 9; break;         /* COMPUTE_CAPABILITY_MAJOR */
    case 76: *value = 0; break;         /* COMPUTE_CAPABILITY_MINOR */
    case 81: *value = 233472; break;    /* MAX_SHARED_MEMORY_PER_MULTIPROCESSOR, 228 KiB */
    case 82: *value = 65536; break;     /* MAX_REGISTERS_PER_MULTIPROCESSOR */
    case 83: *value = 1; break;         /* MANAGED_MEMORY */
    case 97: *value = 232448; break;    /* MAX_SHARED_MEMORY_PER_BLOCK_OPTIN, 227 KiB */
    case 106: *value = 32; break;       /* MAX_BLOCKS_PER_MULTIPROCESSOR */
    case 115: *value = 1; break;        /* MEMORY_POOLS_SUPPORTED */
    default: *value = 0;
  }
  return CUDA_SUCCESS;
}

API CUresult cuDeviceGetDefaultMemPool(void **pool, int device) {
  (void)device;
  *pool = (void *)0x9001;
  return CUDA_SUCCESS;
}

API CUresult cuMemPoolSetAttribute(void *pool, unsigned attribute, void *value) {
  (void)pool, (void)attribute, (void)value;
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- context and streams */

static void *const context = (void *)0xC0FFEE00;

API CUresult cuCtxCreate_v2(void **created, unsigned flags, int device) {
  (void)flags, (void)device;
  *created = context;
  return CUDA_SUCCESS;
}

API CUresult cuDevicePrimaryCtxRetain(void **retained, int device) {
  (void)device;
  *retained = context;
  return CUDA_SUCCESS;
}

API CUresult cuCtxSetCurrent(void *current) {
  (void)current;
  return CUDA_SUCCESS;
}

API CUresult cuCtxGetCurrent(void **current) {
  *current = context;
  return CUDA_SUCCESS;
}

API CUresult cuCtxSetLimit(int limit, size_t value) {
  (void)limit, (void)value;
  return CUDA_SUCCESS;
}

API CUresult cuStreamCreate(void **stream, unsigned flags) {
  static uintptr_t streams = 0x5000;
  (void)flags;
  pthread_mutex_lock(&lock);
  *stream = (void *)++streams;
  pthread_mutex_unlock(&lock);
  return CUDA_SUCCESS;
}

API CUresult cuStreamSynchronize(void *stream) {
  (void)stream;
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- memory */

/* Each allocation is its own mapping, its length kept just before it (one page in front), so that a
 * free needs no table. MAP_NORESERVE: Taichi reserves large pools it never touches here. */
static void *allocate(size_t bytes) {
  size_t length = PAGE + ((bytes ? bytes : 1) + PAGE - 1) / PAGE * PAGE;
  char *base = mmap(NULL, length, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (base == MAP_FAILED) return NULL;
  *(size_t *)base = length;
  return base + PAGE;
}

static void release(void *pointer) {
  if (!pointer) return;
  char *base = (char *)pointer - PAGE;
  munmap(base, *(size_t *)base);
}

/* Zeroes large ranges by dropping their pages (they read back as zeros) instead of writing them. */
static void fill_zero(void *destination, size_t bytes) {
  uintptr_t start = (uintptr_t)destination, end = start + bytes;
  uintptr_t first = (start + PAGE - 1) & ~(PAGE - 1), last = end & ~(PAGE - 1);
  if (last > first + (1u << 20)) {
    memset(destination, 0, first - start);
    madvise((void *)first, last - first, MADV_DONTNEED);
    memset((void *)last, 0, end - last);
  } else {
    memset(destination, 0, bytes);
  }
}

API CUresult cuMemAlloc_v2(void **pointer, size_t bytes) {
  *pointer = allocate(bytes);
  return *pointer ? CUDA_SUCCESS : CUDA_ERROR_OUT_OF_MEMORY;
}

API CUresult cuMemAllocAsync(void **pointer, size_t bytes, void *stream) {
  (void)stream;
  return cuMemAlloc_v2(pointer, bytes);
}

API CUresult cuMemAllocManaged(void **pointer, size_t bytes, unsigned flags) {
  (void)flags;
  return cuMemAlloc_v2(pointer, bytes);
}

API CUresult cuMemFree_v2(void *pointer) {
  release(pointer);
  return CUDA_SUCCESS;
}

API CUresult cuMemFreeAsync(void *pointer, void *stream) {
  (void)stream;
  release(pointer);
  return CUDA_SUCCESS;
}

API CUresult cuMemAdvise(void *pointer, size_t bytes, unsigned advice, int device) {
  (void)pointer, (void)bytes, (void)advice, (void)device;
  return CUDA_SUCCESS;
}

API CUresult cuMemGetInfo_v2(size_t *free_bytes, size_t *total_bytes) {
  *free_bytes = MEMORY_BYTES - (1ull << 30);
  *total_bytes = MEMORY_BYTES;
  return CUDA_SUCCESS;
}

API CUresult cuPointerGetAttribute(void *data, unsigned attribute, void *pointer) {
  switch (attribute) { /* CUpointer_attribute */
    case 1: *(void **)data = context; break; /* CONTEXT */
    case 2: *(unsigned *)data = 2; break;    /* MEMORY_TYPE: CU_MEMORYTYPE_DEVICE */
    case 3: *(void **)data = pointer; break; /* DEVICE_POINTER */
    case 4: *(void **)data = NULL; break;    /* HOST_POINTER */
    case 9: *(int *)data = 0; break;         /* DEVICE_ORDINAL */
    default: *(unsigned long long *)data = 0;
  }
  return CUDA_SUCCESS;
}

API CUresult cuMemcpyHtoD_v2(void *destination, const void *source, size_t bytes) {
  if (bytes) memcpy(destination, source, bytes);
  return CUDA_SUCCESS;
}

API CUresult cuMemcpyDtoH_v2(void *destination, const void *source, size_t bytes) {
  if (bytes) memcpy(destination, source, bytes);
  return CUDA_SUCCESS;
}

API CUresult cuMemcpyDtoD_v2(void *destination, const void *source, size_t bytes) {
  if (bytes) memmove(destination, source, bytes);
  return CUDA_SUCCESS;
}

API CUresult cuMemcpyHtoDAsync_v2(void *destination, const void *source, size_t bytes, void *stream) {
  (void)stream;
  return cuMemcpyHtoD_v2(destination, source, bytes);
}

API CUresult cuMemcpyDtoHAsync_v2(void *destination, const void *source, size_t bytes, void *stream) {
  (void)stream;
  return cuMemcpyDtoH_v2(destination, source, bytes);
}

API CUresult cuMemsetD8_v2(void *destination, unsigned char value, size_t count) {
  if (!count) return CUDA_SUCCESS;
  if (value == 0)
    fill_zero(destination, count);
  else
    memset(destination, value, count);
  return CUDA_SUCCESS;
}

API CUresult cuMemsetD32_v2(void *destination, unsigned value, size_t count) {
  if (!count) return CUDA_SUCCESS;
  if (value == 0) {
    fill_zero(destination, count * 4);
  } else {
    unsigned *word = destination;
    for (size_t i = 0; i < count; i++) word[i] = value;
  }
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- modules and kernels */

typedef struct {
  int index; /* the NNNN of its ptx/module_NNNN.ptx */
} module_t;

typedef struct {
  int module;
  char name[512];
} function_t;

/* Writes the PTX image to ptx/module_NNNN.ptx. Taichi 1.7.4 passes no JIT options: the driver compiles
 * with its defaults, which are ptxas's. */
API CUresult cuModuleLoadDataEx(void **loaded, const void *image, unsigned options, unsigned *option_names,
                                void **option_values) {
  (void)options, (void)option_names, (void)option_values;
  char path[4096 + 32];
  pthread_mutex_lock(&lock);
  if (!launches) { /* cuInit failed or was never called: nowhere to write */
    pthread_mutex_unlock(&lock);
    return CUDA_ERROR_NOT_INITIALIZED;
  }
  int index = modules_loaded++;
  pthread_mutex_unlock(&lock);
  snprintf(path, sizeof path, "%s/module_%04d.ptx", ptx_dir, index);
  FILE *file = fopen(path, "wb");
  size_t length = strlen(image);
  int written = file && fwrite(image, 1, length, file) == length;
  if (file && fclose(file) != 0) written = 0;
  if (!written) {
    fprintf(stderr, "cuda_stub: cannot write %s: %s\n", path, strerror(errno));
    return CUDA_ERROR_OPERATING_SYSTEM;
  }
  module_t *module = calloc(1, sizeof *module);
  if (!module) return CUDA_ERROR_OUT_OF_MEMORY;
  module->index = index;
  *loaded = module;
  return CUDA_SUCCESS;
}

API CUresult cuModuleGetFunction(void **found, void *module, const char *name) {
  function_t *function = calloc(1, sizeof *function);
  if (!function) return CUDA_ERROR_OUT_OF_MEMORY;
  function->module = module ? ((module_t *)module)->index : -1;
  snprintf(function->name, sizeof function->name, "%s", name);
  *found = function;
  return CUDA_SUCCESS;
}

API CUresult cuFuncGetAttribute(int *value, unsigned attribute, void *function) {
  (void)function;
  switch (attribute) { /* CUfunction_attribute; unknown until ptxas runs, so the device's limits */
    case 0: *value = 1024; break;   /* MAX_THREADS_PER_BLOCK */
    case 4: *value = 32; break;     /* NUM_REGS */
    case 5: *value = 86; break;     /* PTX_VERSION: Taichi 1.7.4 emits sm_86 PTX */
    case 6: *value = 90; break;     /* BINARY_VERSION */
    case 8: *value = 232448; break; /* MAX_DYNAMIC_SHARED_SIZE_BYTES */
    default: *value = 0;
  }
  return CUDA_SUCCESS;
}

API CUresult cuFuncSetAttribute(void *function, int attribute, int value) {
  (void)function, (void)attribute, (void)value;
  return CUDA_SUCCESS;
}

API CUresult cuOccupancyMaxActiveBlocksPerMultiprocessor(int *blocks, void *function, int block_size,
                                                         size_t shared_bytes) {
  (void)function, (void)shared_bytes;
  int most = block_size > 0 ? 2048 / block_size : 1; /* threads an SM holds, 32 blocks at most */
  *blocks = most > 32 ? 32 : most < 1 ? 1 : most;
  return CUDA_SUCCESS;
}

/* Runs nothing: one line in launches.log. */
API CUresult cuLaunchKernel(void *function, unsigned grid_x, unsigned grid_y, unsigned grid_z, unsigned block_x,
                            unsigned block_y, unsigned block_z, unsigned shared_bytes, void *stream,
                            void **parameters, void **extra) {
  (void)stream, (void)parameters, (void)extra;
  const function_t *f = function;
  if (launches)
    fprintf(launches, "module %04d %s grid=%u,%u,%u block=%u,%u,%u shmem=%u\n", f ? f->module : -1,
            f ? f->name : "?", grid_x, grid_y, grid_z, block_x, block_y, block_z, shared_bytes);
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- events */

API CUresult cuEventCreate(void **event, unsigned flags) {
  (void)flags;
  *event = calloc(1, 16);
  return *event ? CUDA_SUCCESS : CUDA_ERROR_OUT_OF_MEMORY;
}

API CUresult cuEventDestroy(void *event) {
  free(event);
  return CUDA_SUCCESS;
}

API CUresult cuEventRecord(void *event, void *stream) {
  (void)event, (void)stream;
  return CUDA_SUCCESS;
}

API CUresult cuEventSynchronize(void *event) {
  (void)event;
  return CUDA_SUCCESS;
}

API CUresult cuEventElapsedTime(float *milliseconds, void *start, void *end) {
  (void)start, (void)end;
  *milliseconds = 0.0f;
  return CUDA_SUCCESS;
}

/* ---------------------------------------------------------------------------------- graphics interop */
/* Taichi loads these for CUDA-Vulkan interop (its GGUI window on CUDA); the simulator never calls them. */

API CUresult cuImportExternalMemory(void **memory, const void *description) {
  (void)description;
  *memory = (void *)0x7001;
  return CUDA_SUCCESS;
}

API CUresult cuExternalMemoryGetMappedBuffer(void **pointer, void *memory, const void *description) {
  (void)memory, (void)description;
  *pointer = allocate(1 << 20);
  return *pointer ? CUDA_SUCCESS : CUDA_ERROR_OUT_OF_MEMORY;
}

API CUresult cuExternalMemoryGetMappedMipmappedArray(void **array, void *memory, const void *description) {
  (void)memory, (void)description;
  *array = (void *)0x7002;
  return CUDA_SUCCESS;
}

API CUresult cuMipmappedArrayGetLevel(void **level_array, void *array, unsigned level) {
  (void)array, (void)level;
  *level_array = (void *)0x7003;
  return CUDA_SUCCESS;
}

API CUresult cuSurfObjectCreate(unsigned long long *surface, const void *description) {
  (void)description;
  *surface = 1;
  return CUDA_SUCCESS;
}

API CUresult cuImportExternalSemaphore(void **semaphore, const void *description) {
  (void)description;
  *semaphore = (void *)0x7004;
  return CUDA_SUCCESS;
}

API CUresult cuSignalExternalSemaphoresAsync(const void *semaphores, const void *parameters, unsigned count,
                                             void *stream) {
  (void)semaphores, (void)parameters, (void)count, (void)stream;
  return CUDA_SUCCESS;
}

API CUresult cuWaitExternalSemaphoresAsync(const void *semaphores, const void *parameters, unsigned count,
                                           void *stream) {
  (void)semaphores, (void)parameters, (void)count, (void)stream;
  return CUDA_SUCCESS;
}
