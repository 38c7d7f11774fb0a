build-san/obj/common/tile.o: common/tile.c common/tile.h common/imgio.h \
 common/scene.h common/vec.h
common/tile.h:
common/imgio.h:
common/scene.h:
common/vec.h:
