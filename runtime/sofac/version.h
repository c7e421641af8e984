// sofac's header-only C++ runtime: version of the runtime the generated code is built against.
// Kept equal to sofac.__version__ (tests/test_packaging.py checks it). The rest of the runtime
// (states, assembly, solvers) comes with the generate and build stages, which do not exist yet.
#pragma once

#define SOFAC_RUNTIME_VERSION_MAJOR 0
#define SOFAC_RUNTIME_VERSION_MINOR 1
#define SOFAC_RUNTIME_VERSION_PATCH 0
#define SOFAC_RUNTIME_VERSION "0.1.0"
