# hermes_tool_help(<target>): the usage text of binary <target> lives in
# tools/help/<target>.txt, the one source of that text. The binary prints it
# (`<target> --help`) from the generated header hermes_help/<target>.h
# (hermes_help::kText, regenerated when the file changes); ./hermes prints the
# same file for `--help` without building anything. ctest help_texts_match_the_binaries
# checks that the two agree. A target without such a file is left alone.
include_guard(GLOBAL)
get_filename_component(HERMES_HELP_DIR ${CMAKE_CURRENT_LIST_DIR}/../tools/help ABSOLUTE)
set(HERMES_EMBED_HELP_SCRIPT ${CMAKE_CURRENT_LIST_DIR}/EmbedHelp.cmake)
# A help file added later re-runs the configuration.
file(GLOB _hermes_help_files CONFIGURE_DEPENDS ${HERMES_HELP_DIR}/*.txt)

function(hermes_tool_help target)
  set(txt ${HERMES_HELP_DIR}/${target}.txt)
  if(NOT EXISTS ${txt})
    return()
  endif()
  set(dir ${CMAKE_BINARY_DIR}/generated)
  set(header ${dir}/hermes_help/${target}.h)
  add_custom_command(OUTPUT ${header}
    COMMAND ${CMAKE_COMMAND} -DIN=${txt} -DOUT=${header} -DNAME=${target}
            -P ${HERMES_EMBED_HELP_SCRIPT}
    DEPENDS ${txt} ${HERMES_EMBED_HELP_SCRIPT}
    COMMENT "Embedding tools/help/${target}.txt"
    VERBATIM)
  target_sources(${target} PRIVATE ${header})
  target_include_directories(${target} PRIVATE ${dir})
  set_property(GLOBAL APPEND PROPERTY HERMES_HELP_TARGETS ${target})
endfunction()
