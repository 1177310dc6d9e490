// supernodal_numeric_kernel.cpp built for x86-64-v3 (CMake gives this file -march=x86-64-v3).
#define SOFTSHELL_KERNEL_X86_64_V3
#include "supernodal_numeric_kernel.cpp"
