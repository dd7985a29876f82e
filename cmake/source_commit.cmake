# Writes OUT, a header naming the commit the lab is built from (lab/source.h), at every build:
#   cmake -DSOURCE_DIR=... -DOUT=... -P source_commit.cmake
# The commit is `git rev-parse --short HEAD`, or "unknown" outside a git checkout (a source
# tarball, or no git); "dirty" says whether the sources the lab is built from differed from that
# commit when it was built. OUT is only rewritten when its text changes, so a build that changes
# neither recompiles nothing.
set(commit "unknown")
set(dirty 0)
find_package(Git QUIET)
if(GIT_FOUND)
  execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --short HEAD
                  WORKING_DIRECTORY ${SOURCE_DIR} RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  if(rc EQUAL 0 AND NOT out STREQUAL "")
    set(commit ${out})
    execute_process(COMMAND ${GIT_EXECUTABLE} diff --quiet HEAD --
                            engine nodes lab cli viewer-offline CMakeLists.txt
                    WORKING_DIRECTORY ${SOURCE_DIR} RESULT_VARIABLE rc ERROR_QUIET)
    if(NOT rc EQUAL 0)
      set(dirty 1)
    endif()
  endif()
endif()
set(text "// Written by cmake/source_commit.cmake at build time; do not edit.\n#pragma once\n#define GRAINS_SOURCE_COMMIT \"${commit}\"\n#define GRAINS_SOURCE_DIRTY ${dirty}\n")
if(EXISTS ${OUT})
  file(READ ${OUT} old)
else()
  set(old "")
endif()
if(NOT old STREQUAL text)
  file(WRITE ${OUT} "${text}")
endif()
