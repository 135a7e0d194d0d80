# ctest "core_sources_are_ros_free" (besides building the ROS-free tree on its
# own, ./hermes test checks the sources): no source of a ROS-free library
# includes a ROS header. Run as
#   cmake -DROOT=<source dir> -P cmake/CheckRosFree.cmake
set(dirs src hermes_distill hermes_agent/core hermes_server/core hermes_transport hermes_system)
set(ros_headers "ros|nodelet|pluginlib|sensor_msgs|std_msgs|geometry_msgs|nav_msgs|visualization_msgs|tf|tf2|tf2_ros|rosbag|image_transport|cv_bridge|message_filters|hermes_msgs")
set(found "")
foreach(dir ${dirs})
  file(GLOB_RECURSE files ${ROOT}/${dir}/*.h ${ROOT}/${dir}/*.hpp ${ROOT}/${dir}/*.cc ${ROOT}/${dir}/*.cpp)
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"](${ros_headers})/")
    if(lines)
      list(APPEND found "${f}: ${lines}")
    endif()
  endforeach()
endforeach()
if(found)
  string(REPLACE ";" "\n  " found "${found}")
  message(FATAL_ERROR "ROS headers in ROS-free libraries (move the code to a nodelet/node):\n  ${found}")
endif()
message(STATUS "ROS-free libraries include no ROS header")
