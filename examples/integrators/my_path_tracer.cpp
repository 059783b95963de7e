// Adds the student's path tracer (examples/my_path_tracer.hpp) to the command-line
// renderer as `-a mypt`. The Makefile links every .cpp of its INTEGRATORS variable into
// build/smallvcm (this file by default); the registration object below runs before main
// and puts the integrator into the registry that -a and --help read. Your own integrator
// works the same way:
//     make build/smallvcm INTEGRATORS="examples/integrators/my_path_tracer.cpp mine.cpp"
#include "examples/my_path_tracer.hpp"

static const smallvcm::IntegratorRegistration kMyPathTracer(MyPathTracerIntegrator());
