# ctest "libraries_include_only_layers_below": a library includes headers of the
# libraries below it and of none beside or above it (tests and tools may reach
# further: they exercise both ends). The layers:
#   core (src) <- distill <- agent core;  core <- distill <- server core (the
#   downlink ranks landmarks with the uplink's scores);  core <- transport;
#   system (offline runner) and the ROS packages sit on top. Run as
#   cmake -DROOT=<source dir> -P cmake/CheckLayers.cmake
set(found "")
function(forbid dir pattern)
  file(GLOB_RECURSE files ${ROOT}/${dir}/src/*.cc ${ROOT}/${dir}/src/*.h ${ROOT}/${dir}/include/*.h)
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]hermes/(${pattern})/")
    if(lines)
      set(found "${found}\n  ${f}: ${lines}" PARENT_SCOPE)
    endif()
  endforeach()
endfunction()
forbid(src "distill|agent|server|transport|system")
forbid(hermes_distill "agent|server|transport|system")
forbid(hermes_agent/core "server|transport|system")
forbid(hermes_server/core "agent|transport|system")
forbid(hermes_transport "agent|server|system")
forbid(hermes_server "agent")
if(found)
  message(FATAL_ERROR "includes across the layers (move the shared types down to core):${found}")
endif()
message(STATUS "every library includes only the layers below it")
