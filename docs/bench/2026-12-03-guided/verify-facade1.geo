scene facade1, database verify-facade1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 6 | 1161 | 96.5 % | 99.4 % | 100.0 % | 0.13 | 1161 | 92.3 % | 99.2 % | 100.0 % |
| view0.png view2.png | 6 | 639 | 94.5 % | 99.7 % | 100.0 % | 0.16 | 639 | 88.9 % | 99.1 % | 99.8 % |
| view0.png view3.png | 6 | 294 | 95.2 % | 99.3 % | 100.0 % | 0.17 | 294 | 88.4 % | 99.0 % | 100.0 % |
| view0.png view4.png | 2 | 151 | 70.9 % | 76.2 % | 76.2 % | 0.32 | 151 | 57.0 % | 62.9 % | 62.9 % |
| view1.png view2.png | 6 | 851 | 96.8 % | 99.5 % | 100.0 % | 0.17 | 851 | 92.0 % | 98.7 % | 99.9 % |
| view1.png view3.png | 6 | 414 | 97.6 % | 100.0 % | 100.0 % | 0.17 | 414 | 92.8 % | 99.3 % | 100.0 % |
| view1.png view4.png | 6 | 303 | 97.4 % | 99.0 % | 100.0 % | 0.14 | 303 | 90.8 % | 98.0 % | 99.7 % |
| view2.png view3.png | 6 | 828 | 96.0 % | 99.8 % | 100.0 % | 0.18 | 828 | 92.4 % | 99.4 % | 99.9 % |
| view2.png view4.png | 6 | 436 | 95.6 % | 99.5 % | 100.0 % | 0.16 | 436 | 90.6 % | 98.4 % | 100.0 % |
| view3.png view4.png | 6 | 753 | 94.6 % | 99.1 % | 100.0 % | 0.16 | 753 | 90.0 % | 98.1 % | 99.9 % |
| all pairs |  | 5830 | 95.3 % | 98.9 % | 99.4 % | 0.16 | 5830 | 90.3 % | 97.9 % | 99.0 % |

model: 5/5 images registered, 1284 points
relative rotation error (every pair of images, no alignment): mean 0.019° max 0.034°
after a similarity alignment of the camera centres: centre error mean 0.0020 max 0.0037 (scene units), rotation error mean 0.061° max 0.074°
