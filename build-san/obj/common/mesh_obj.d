build-san/obj/common/mesh_obj.o: common/mesh_obj.c common/mesh_obj.h \
 common/asset.h common/scene.h common/vec.h common/log.h
common/mesh_obj.h:
common/asset.h:
common/scene.h:
common/vec.h:
common/log.h:
