build-san/obj/common/light.o: common/light.c common/light.h \
 common/scene.h common/vec.h common/log.h
common/light.h:
common/scene.h:
common/vec.h:
common/log.h:
