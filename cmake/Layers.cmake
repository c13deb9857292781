# The module graph, checked when CMake configures (docs/DEVELOPING.md, "Layers"): a module links
# only the modules below it, and no header of a module below `model` includes the scene loader, the
# model or the renderer. A change that breaks either stops the configuration with a message naming
# the offending link or #include.

# Each module and the flatland modules it may reach through its links (directly or not).
set(FLATLAND_LAYERS
  "files:"
  "sim:"
  "design:sim"
  "scene:sim"
  "api:scene,sim,design"
  "camera:"
  "render:scene,sim,camera"
  "model:render,scene,sim,camera,vision,control"
  "vision:camera,sim"
  "calibration:vision,camera,sim"
  "control:sim"
  "identify:sim"
  "drivers:control,vision,render,calibration,model,scene,camera,sim,files"
  "studies:drivers,control,vision,render,calibration,model,scene,camera,sim,files"
  "cluster:sim")
# Modules whose headers must not include flatland/scene, flatland/model or flatland/render.
set(FLATLAND_BELOW_MODEL files sim camera vision calibration control identify cluster design)
# Modules that read the scene's sections but sit below the compiled Model: no flatland/model.
set(FLATLAND_BELOW_MODEL_WITH_SCENE render api)

# The flatland modules that `target` links, transitively (flatland_x targets, by module name).
function(flatland_module_closure target out)
  set(seen "")
  set(queue ${target})
  while(queue)
    list(POP_FRONT queue current)
    foreach(property LINK_LIBRARIES INTERFACE_LINK_LIBRARIES)
      get_target_property(links ${current} ${property})
      if(NOT links)
        continue()
      endif()
      foreach(link ${links})
        string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" link "${link}")
        if(link MATCHES "^flatland::([a-z]+)$")
          set(link flatland_${CMAKE_MATCH_1})
        endif()
        if(link MATCHES "^flatland_([a-z]+)$" AND TARGET ${link})
          if(NOT CMAKE_MATCH_1 IN_LIST seen)
            list(APPEND seen ${CMAKE_MATCH_1})
            list(APPEND queue ${link})
          endif()
        endif()
      endforeach()
    endforeach()
  endwhile()
  set(${out} ${seen} PARENT_SCOPE)
endfunction()

function(flatland_check_layers)
  foreach(entry ${FLATLAND_LAYERS})
    string(REPLACE ":" ";" parts "${entry}")
    list(GET parts 0 module)
    list(LENGTH parts n)
    set(allowed "")
    if(n GREATER 1)
      list(GET parts 1 allowed)
      string(REPLACE "," ";" allowed "${allowed}")
    endif()
    if(NOT TARGET flatland_${module})
      continue()  # an optional module not built here (cluster without MPI)
    endif()
    flatland_module_closure(flatland_${module} reached)
    foreach(other ${reached})
      if(NOT other IN_LIST allowed)
        message(FATAL_ERROR "layers: flatland::${module} links flatland::${other}, which is not "
                            "below it (cmake/Layers.cmake; docs/DEVELOPING.md, \"Layers\")")
      endif()
    endforeach()
  endforeach()
  foreach(module ${FLATLAND_BELOW_MODEL} ${FLATLAND_BELOW_MODEL_WITH_SCENE})
    set(forbidden "scene|model|render")
    if(module IN_LIST FLATLAND_BELOW_MODEL_WITH_SCENE)
      set(forbidden "model")
    endif()
    file(GLOB_RECURSE headers ${PROJECT_SOURCE_DIR}/${module}/include/*.hpp)
    foreach(header ${headers})
      file(STRINGS ${header} bad REGEX "#include [<\"]flatland/(${forbidden})/")
      if(bad)
        file(RELATIVE_PATH name ${PROJECT_SOURCE_DIR} ${header})
        list(GET bad 0 first)
        message(FATAL_ERROR "layers: ${name} (below model) has ${first}")
      endif()
    endforeach()
  endforeach()
endfunction()
