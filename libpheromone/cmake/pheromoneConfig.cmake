# CMake package configuration of libpheromone, installed by libpheromone/install.sh into
# <prefix>/lib/cmake/pheromone. Use:
#   find_package(pheromone REQUIRED)
#   target_link_libraries(my_node PRIVATE pheromone::pheromone)         # libpheromone.so
#   target_link_libraries(my_node PRIVATE pheromone::pheromone_static)  # libpheromone.a
# Both give the include directory of pheromone.h and pheromone.hpp.
get_filename_component(_pheromone_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)

if(NOT TARGET pheromone::pheromone)
  add_library(pheromone::pheromone SHARED IMPORTED)
  set_target_properties(pheromone::pheromone PROPERTIES
    IMPORTED_LOCATION "${_pheromone_prefix}/lib/libpheromone.so"
    IMPORTED_SONAME "libpheromone.so"
    INTERFACE_INCLUDE_DIRECTORIES "${_pheromone_prefix}/include")
endif()

if(NOT TARGET pheromone::pheromone_static)
  find_package(Threads REQUIRED)
  add_library(pheromone::pheromone_static STATIC IMPORTED)
  set_target_properties(pheromone::pheromone_static PROPERTIES
    IMPORTED_LOCATION "${_pheromone_prefix}/lib/libpheromone.a"
    INTERFACE_INCLUDE_DIRECTORIES "${_pheromone_prefix}/include"
    INTERFACE_LINK_LIBRARIES "Threads::Threads;${CMAKE_DL_LIBS};m;rt;gcc_s")
endif()

set(pheromone_INCLUDE_DIRS "${_pheromone_prefix}/include")
set(pheromone_LIBRARIES pheromone::pheromone)
unset(_pheromone_prefix)
