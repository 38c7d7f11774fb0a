build-san/obj/common/material.o: common/material.c common/material.h \
 common/scene.h common/vec.h
common/material.h:
common/scene.h:
common/vec.h:
