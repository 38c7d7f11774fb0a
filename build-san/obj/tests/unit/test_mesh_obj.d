build-san/obj/tests/unit/test_mesh_obj.o: tests/unit/test_mesh_obj.c \
 common/mesh_obj.h common/asset.h common/scene.h common/vec.h
common/mesh_obj.h:
common/asset.h:
common/scene.h:
common/vec.h:
