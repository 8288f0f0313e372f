# Loaded by CMake as a toolchain file (CMAKE_TOOLCHAIN_FILE, set for cargo's
# build scripts in .cargo/config.toml) when `rubullet-sys` builds Bullet 3
# from its bundled sources. That build's `install` step builds every target
# of Bullet's tree: the OpenGL example browser, the shared-memory servers,
# the demos and libraries nothing links (about half of its 876 objects).
#
# At the end of the configuration this script keeps the `cbullet` library
# (the C API the engine links) and every target it links, directly or not,
# and replaces the sources of every other target by one empty file, so they
# still exist for Bullet's own install rules but cost nothing to build. The
# kept libraries are compiled from the same sources with the same flags as
# before: the engine's code is unchanged.
#
# A project without a `cbullet` target (any other CMake build run by a build
# script) is left as it is.

if(NOT COMMAND realitygap_trim_bullet)
  function(realitygap_collect_targets dir out)
    get_property(here DIRECTORY "${dir}" PROPERTY BUILDSYSTEM_TARGETS)
    get_property(subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
    foreach(sub IN LISTS subdirs)
      realitygap_collect_targets("${sub}" more)
      list(APPEND here ${more})
    endforeach()
    set(${out} ${here} PARENT_SCOPE)
  endfunction()

  function(realitygap_trim_bullet)
    if(NOT TARGET cbullet)
      return()
    endif()
    # The link closure of cbullet.
    set(keep cbullet)
    set(queue cbullet)
    while(queue)
      list(POP_FRONT queue t)
      get_target_property(libs ${t} LINK_LIBRARIES)
      if(NOT libs)
        continue()
      endif()
      foreach(l IN LISTS libs)
        if(TARGET ${l})
          get_target_property(imported ${l} IMPORTED)
          list(FIND keep ${l} seen)
          if(NOT imported AND seen EQUAL -1)
            list(APPEND keep ${l})
            list(APPEND queue ${l})
          endif()
        endif()
      endforeach()
    endwhile()
    # The GUI (OpenGL window, gwen widgets, the example browser): linked by
    # cbullet for its GUI connection modes, which realitygap never opens.
    list(REMOVE_ITEM keep gwen OpenGLWindow BulletRoboticsGUI BulletExampleBrowserLib)
    set(unity_safe LinearMath BulletCollision BulletDynamics BulletInverseDynamics Bullet3Common)
    set(empty_lib "${CMAKE_BINARY_DIR}/realitygap_trimmed_empty.cpp")
    set(empty_main "${CMAKE_BINARY_DIR}/realitygap_trimmed_main.cpp")
    file(WRITE "${empty_lib}" "// a target realitygap does not use\n")
    file(WRITE "${empty_main}" "int main() { return 0; }\n")
    realitygap_collect_targets("${CMAKE_SOURCE_DIR}" all)
    set(trimmed "")
    foreach(t IN LISTS all)
      list(FIND keep ${t} kept)
      if(NOT kept EQUAL -1)
        list(FIND unity_safe ${t} safe)
        if(NOT safe EQUAL -1)
          set_property(TARGET ${t} PROPERTY UNITY_BUILD ON)
          set_property(TARGET ${t} PROPERTY UNITY_BUILD_BATCH_SIZE 16)
        endif()
        continue()
      endif()
      get_target_property(type ${t} TYPE)
      if(type STREQUAL "EXECUTABLE")
        set_property(TARGET ${t} PROPERTY SOURCES "${empty_main}")
        set_property(TARGET ${t} PROPERTY LINK_LIBRARIES "")
        list(APPEND trimmed ${t})
      elseif(type STREQUAL "STATIC_LIBRARY" OR type STREQUAL "SHARED_LIBRARY" OR type STREQUAL "MODULE_LIBRARY" OR type STREQUAL "OBJECT_LIBRARY")
        set_property(TARGET ${t} PROPERTY SOURCES "${empty_lib}")
        set_property(TARGET ${t} PROPERTY LINK_LIBRARIES "")
        list(APPEND trimmed ${t})
      endif()
    endforeach()
    list(LENGTH keep nkeep)
    list(LENGTH trimmed ntrim)
    message(STATUS "realitygap: building cbullet and the ${nkeep} targets it links; ${ntrim} others emptied: ${trimmed}")
  endfunction()
endif()

# Once per configuration (a toolchain file may be read more than once; in a
# try_compile project there is no cbullet and the call does nothing).
get_property(realitygap_deferred GLOBAL PROPERTY REALITYGAP_TRIM_DEFERRED)
if(NOT realitygap_deferred)
  set_property(GLOBAL PROPERTY REALITYGAP_TRIM_DEFERRED 1)
  cmake_language(DEFER CALL realitygap_trim_bullet)
endif()
