/* The C API of the Open Dynamics Engine that realitygap-engine-ode binds
 * (bindgen, build.rs), plus vsnprintf to format ODE's messages. */
#include <ode/ode.h>
#include <stdio.h>
